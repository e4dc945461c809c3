// The RCP bridge's objects in the signal registry (ioc/rcp_signals.hpp): declared while the IOC
// runs as the beacon announces them (after the registry is frozen: the cycle never sees them),
// withdrawn when they go; a name already taken is logged and changes nothing else.
#include "../bridge/rcp_harness.hpp"
#include "ioc/rcp_signals.hpp"

#include <gtest/gtest.h>

#include <sstream>

using namespace beamctl;
using namespace beamctl::bridge::rcp;
using namespace beamctl::bridge::rcp::test;

namespace {

struct RegistryHarness {
    registry::Registry reg;
    std::unique_ptr<Harness> h;
    RegistryHarness() {
        reg.freeze(); // as in a running IOC
        BridgeConfig c = Harness::config();
        c.on_object = [this](const BridgeConfig::ObjectEvent& e) { ioc::on_rcp_object(reg, e); };
        h = std::make_unique<Harness>(c);
    }
};

} // namespace

TEST(IocRcpSignals, ObjectsAreDeclaredWhenAnnouncedAndWithdrawnWhenTheyGo) {
    RegistryHarness r;
    EXPECT_EQ(r.reg.size(), 0u);
    r.h->announce("app", {obj(1, ObjectType::AI, DataType::Float64, "Temp"),
                          obj(2, ObjectType::AO, DataType::Float32, "Set"),
                          obj(3, ObjectType::BI, DataType::Bool, "Ok"),
                          obj(4, ObjectType::Motor, DataType::Float64, "Stage")});
    const registry::Signal* temp = r.reg.find("rcp.app.Temp");
    ASSERT_NE(temp, nullptr);
    EXPECT_EQ(temp->type, "LREAL");
    EXPECT_EQ(temp->direction, registry::Direction::Input);
    EXPECT_EQ(temp->owner_kind, registry::OwnerKind::Bridge);
    EXPECT_EQ(temp->pv, "T:app:Temp");
    EXPECT_TRUE(temp->loop_only);
    const registry::Signal* set = r.reg.find("rcp.app.Set");
    ASSERT_NE(set, nullptr);
    EXPECT_EQ(set->type, "REAL");
    EXPECT_EQ(set->direction, registry::Direction::Variable);
    ASSERT_NE(r.reg.find("rcp.app.Ok"), nullptr);
    EXPECT_EQ(r.reg.find("rcp.app.Ok")->type, "BOOL");
    ASSERT_NE(r.reg.find("rcp.app.Stage"), nullptr);
    EXPECT_EQ(r.reg.find("rcp.app.Stage")->pv, "T:app:Stage");
    EXPECT_EQ(r.reg.find("rcp.app.Stage")->direction, registry::Direction::Variable);
    EXPECT_EQ(r.reg.match("rcp.*").size(), 4u);
    std::ostringstream os;
    r.reg.print(os, "rcp.app.T*");
    EXPECT_NE(os.str().find("T:app:Temp"), std::string::npos) << os.str();
    EXPECT_NE(os.str().find("rcp app (AI)"), std::string::npos) << os.str();

    r.h.reset(); // the bridge stops: its objects go
    EXPECT_EQ(r.reg.match("rcp.*").size(), 0u);
}

TEST(IocRcpSignals, ANameTakenByAnotherSignalIsLoggedAndTheObjectKeepsItsPvs) {
    RegistryHarness r;
    registry::Signal other;
    other.name = "rcp.app.Temp";
    other.owner = "someone else";
    other.loop_only = true;
    r.reg.declare_runtime(other);
    r.h->announce("app", {obj(1, ObjectType::AI, DataType::Float64, "Temp")});
    EXPECT_EQ(r.reg.find("rcp.app.Temp")->owner, "someone else");
    EXPECT_TRUE(r.h->exists("T:app:Temp"));
}

TEST(IocRcpSignals, OnlySignalsOfTheLoopMayComeAfterTheFreeze) {
    registry::Registry reg;
    reg.freeze();
    registry::Signal s;
    s.name = "ec0.s1.x";
    s.owner = "ec0";
    EXPECT_THROW(reg.declare(s), Error);
    EXPECT_THROW(reg.declare_runtime(s), Error); // the cycle would see it
    s.loop_only = true;
    reg.declare_runtime(s);
    EXPECT_NE(reg.find("ec0.s1.x"), nullptr);
    reg.withdraw("ec0.s1.x");
    EXPECT_EQ(reg.find("ec0.s1.x"), nullptr);
}
