// How a Database stores what it loads: the flat name index (RecordIndex) against a std::map
// reference, link text deferred from load to init_records (read before and after init, through an
// alias, after its target went away, replaced by a put), records from the record pool.
#include "db_fixture.hpp"
#include "pv/database.hpp"
#include "pv/record_index.hpp"

#include <gtest/gtest.h>

#include <map>
#include <memory>
#include <random>
#include <string>

using namespace beamctl;
using namespace beamctl::pv;

namespace {

std::unique_ptr<Record> make_ao(const std::string& name) {
    auto r = RecordTypes::global().find("ao")->create();
    copy_string(r->name_, sizeof r->name_, name);
    return r;
}

struct Storage : DbTest {};

} // namespace

TEST(RecordIndex, AgreesWithAMapThroughInsertsAndErases) {
    std::vector<std::unique_ptr<Record>> recs;
    for (int i = 0; i < 3000; ++i) recs.push_back(make_ao("r" + std::to_string(i)));
    RecordIndex index;
    std::map<std::string, Record*> ref;
    std::mt19937 rng(7);
    for (int step = 0; step < 40000; ++step) {
        Record* r = recs[rng() % recs.size()].get();
        std::string name(r->name());
        if (ref.count(name)) {
            if (rng() % 3 == 0) {
                ASSERT_EQ(index.erase(name), r) << name;
                ref.erase(name);
            }
        } else {
            index.insert(r);
            ref[name] = r;
        }
        if (step % 997 == 0) // every name, present or not, answers as the map does
            for (auto& x : recs) {
                auto it = ref.find(std::string(x->name()));
                ASSERT_EQ(index.find(x->name()), it == ref.end() ? nullptr : it->second) << x->name();
            }
    }
    EXPECT_EQ(index.size(), ref.size());
    EXPECT_EQ(index.find("nope"), nullptr);
    EXPECT_EQ(index.erase("nope"), nullptr);
}

TEST_F(Storage, RecordsAreFoundAndRemovedByName) {
    std::string text;
    for (int i = 0; i < 500; ++i) text += "record(ao, \"a" + std::to_string(i) + "\") { field(VAL, \"" + std::to_string(i) + "\") }\n";
    load(text.c_str());
    EXPECT_EQ(db.size(), 500u);
    EXPECT_EQ(getd("a321"), 321);
    db.remove("a321");
    EXPECT_EQ(db.find("a321"), nullptr);
    EXPECT_EQ(db.size(), 499u);
    EXPECT_EQ(getd("a499"), 499);
    db.add(make_ao("a321"));
    db.init_records();
    EXPECT_NE(db.find("a321"), nullptr);
}

TEST_F(Storage, LinkTextReadsTheSameBeforeAndAfterInit) {
    db.load(parse_db(R"(
record(ao, "src") {}
record(calc, "c") { field(INPA, "src NPP MS") field(INPB, "src.HOPR CP") field(INPC, "1.5")
                    field(FLNK, "src") }
)",
                     "t.db", {}));
    // before iocInit the texts wait in the database; they read as they will after
    EXPECT_EQ(gets("c.INPA"), "src NPP MS");
    EXPECT_EQ(gets("c.INPB"), "src.HOPR CP NMS");
    EXPECT_EQ(gets("c.INPC"), "1.5");
    EXPECT_EQ(gets("c.FLNK"), "src NPP NMS");
    db.init_records();
    EXPECT_EQ(gets("c.INPA"), "src NPP MS");
    EXPECT_EQ(gets("c.INPB"), "src.HOPR CP NMS");
    EXPECT_EQ(gets("c.INPC"), "1.5");
    EXPECT_EQ(gets("c.FLNK"), "src NPP NMS");
    put("src", 4);
    put("c.PROC", 1);
    EXPECT_EQ(getd("c.A"), 4);
}

TEST_F(Storage, ALinkThroughAnAliasKeepsTheNameWritten) {
    load(R"(
record(ao, "src") { alias("other") field(VAL, "3") }
record(calc, "c") { field(INPA, "other PP") field(CALC, "A") }
)");
    EXPECT_EQ(gets("c.INPA"), "other PP NMS");
    put("c.PROC", 1);
    EXPECT_EQ(getd("c"), 3);
}

TEST_F(Storage, ALinkWhoseTargetIsRemovedKeepsItsTextAndRaisesALinkAlarm) {
    load(R"(
record(ao, "src") { field(VAL, "3") }
record(calc, "c") { field(INPA, "src.VAL PP") field(CALC, "A") }
)");
    db.remove("src");
    EXPECT_EQ(gets("c.INPA"), "src.VAL PP NMS");
    put("c.PROC", 1);
    EXPECT_EQ(getd("c.SEVR"), kInvalid);
    EXPECT_EQ(getd("c.STAT"), kStatLink);
}

TEST_F(Storage, APutReplacesAResolvedLinkAndABadOneLeavesItWorking) {
    load(R"(
record(ao, "a") { field(VAL, "1") }
record(ao, "b") { field(VAL, "2") }
record(calc, "c") { field(INPA, "a") field(CALC, "A") }
)");
    EXPECT_EQ(put_str("c.INPA", "b NPP"), PutStatus::Ok);
    EXPECT_EQ(gets("c.INPA"), "b NPP NMS");
    put("c.PROC", 1);
    EXPECT_EQ(getd("c"), 2);
    EXPECT_NE(put_str("c.INPA", "missing"), PutStatus::Ok); // refused: the old link stays
    EXPECT_EQ(gets("c.INPA"), "b NPP NMS");
    put("b", 5);
    put("c.PROC", 1);
    EXPECT_EQ(getd("c"), 5);
}

TEST_F(Storage, DeferredLinksStillReportErrorsWithFileLineAndColumn) {
    // syntax: at load; a missing record: at init, both with where the field was set
    std::string syntax = load_error("record(calc, \"c\") {\n  field(INPA, \"x PP PP2\")\n}\n");
    EXPECT_NE(syntax.find("bad.db:2:"), std::string::npos) << syntax;
    EXPECT_NE(syntax.find("PP2"), std::string::npos) << syntax;
    std::string missing = load_error("record(calc, \"c\") {\n  field(CALC, \"A\")\n  field(INPA, \"nowhere\")\n}\n");
    EXPECT_NE(missing.find("bad.db:3:"), std::string::npos) << missing;
    EXPECT_NE(missing.find("no record 'nowhere'"), std::string::npos) << missing;
}

TEST_F(Storage, ARecordDefinedTwiceTakesTheLastLink) {
    load(R"(
record(ao, "a") { field(VAL, "1") }
record(ao, "b") { field(VAL, "2") }
record(calc, "c") { field(INPA, "a") field(CALC, "A") }
record(calc, "c") { field(INPA, "b") }
)");
    EXPECT_EQ(gets("c.INPA"), "b NPP NMS");
    put("c.PROC", 1);
    EXPECT_EQ(getd("c"), 2);
}
