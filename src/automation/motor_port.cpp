// Motor records for automation, here or through Channel Access (see motor_port.hpp).
#include "automation/motor_port.hpp"

#include "automation/number_text.hpp"
#include "ca/client.hpp"
#include "core/error.hpp"

#include <cmath>
#include <cstdio>
#include <memory>

namespace beamctl::automation {

namespace {

std::string fmt(double v) { return number_text(v, 6); }

// Success is the callback's word and the position (see motor_port.hpp). `done` is called once:
// emptied when called.
void judge(const std::string& name, bool put_ok, double rbv, double target, double deadband,
           const std::shared_ptr<MotorPort::Done>& done) {
    if (!*done) return;
    const MotorPort::Done d = std::move(*done);
    *done = nullptr;
    if (!put_ok) return d(false, name + " refused or failed the move (at " + fmt(rbv) + ", target " + fmt(target) + ")");
    if (!(std::fabs(rbv - target) <= deadband + 1e-12 * (1 + std::fabs(target))))
        return d(false, name + " ended short at " + fmt(rbv) + " (target " + fmt(target) + ")");
    d(true, {});
}

class LocalMotor final : public MotorPort {
public:
    LocalMotor(pv::Database& db, const std::string& record) : db_(db), name_(record) {
        pv::Record* r = db.find(record);
        if (!r || std::string_view(r->type().name()) != "motor") throw Error("'" + record + "' is not a motor record of this IOC");
        for (auto [field, addr] : {std::pair{"VAL", &val_}, {"RBV", &rbv_}, {"HLM", &hlm_}, {"LLM", &llm_}, {"RDBD", &rdbd_},
                                   {"MRES", &mres_}, {"DMOV", &dmov_}, {"HLS", &hls_}, {"LLS", &lls_}, {"STOP", &stop_}})
            if (!db.resolve(record + "." + field, *addr)) throw Error("motor record '" + record + "' has no field " + field);
    }
    const std::string& name() const override { return name_; }
    State state() const override {
        State s;
        s.connected = true;
        s.rbv = get(rbv_), s.val = get(val_), s.hlm = get(hlm_), s.llm = get(llm_);
        s.deadband = std::max(get(rdbd_), std::fabs(get(mres_)));
        s.dmov = get(dmov_) != 0, s.hls = get(hls_) != 0, s.lls = get(lls_) != 0;
        return s;
    }
    void move(double target, Done done) override {
        auto shared = std::make_shared<Done>(std::move(done));
        const pv::PutStatus st = db_.put(val_, pv::Prim::Double, &target, 1, [this, target, shared](pv::PutStatus s) {
            const State now = state();
            judge(name_, s == pv::PutStatus::Ok, now.rbv, target, now.deadband, shared);
        });
        // A refused put calls back and returns the refusal: judge() acts once.
        if (st != pv::PutStatus::Ok) {
            const State now = state();
            judge(name_, false, now.rbv, target, now.deadband, shared);
        }
    }
    void stop() override {
        const double one = 1;
        db_.put(stop_, pv::Prim::Double, &one, 1);
    }

private:
    double get(const pv::Address& a) const {
        double v = 0;
        db_.get(a, pv::Prim::Double, &v, 1);
        return v;
    }
    pv::Database& db_;
    std::string name_;
    pv::Address val_, rbv_, hlm_, llm_, rdbd_, mres_, dmov_, hls_, lls_, stop_;
};

// Channels and monitors of the fields a port needs; values cached as they arrive.
class CaMotor final : public MotorPort {
public:
    CaMotor(ca::Client& client, const std::string& record) : name_(record), life_(std::make_shared<int>(0)) {
        static const char* kFields[kCount] = {"VAL", "RBV", "HLM", "LLM", "RDBD", "MRES", "DMOV", "HLS", "LLS", "STOP"};
        for (int i = 0; i < kCount; ++i) {
            ch_[i] = client.channel(record + "." + kFields[i]);
            if (i == kStop) continue;
            std::weak_ptr<int> alive = life_;
            mon_[i] = ch_[i]->monitor(pv::kDbeValue | pv::kDbeAlarm, [this, i, alive](const ca::Result& r) {
                if (alive.expired()) return;
                if (r.ok()) v_[i] = r.value.as_double(), have_[i] = true;
            });
        }
    }
    const std::string& name() const override { return name_; }
    State state() const override {
        State s;
        s.connected = true;
        for (int i = 0; i < kCount; ++i) s.connected = s.connected && ch_[i]->connected() && (i == kStop || have_[i]);
        s.val = v_[kVal], s.rbv = v_[kRbv], s.hlm = v_[kHlm], s.llm = v_[kLlm];
        s.deadband = std::max(v_[kRdbd], std::fabs(v_[kMres]));
        s.dmov = v_[kDmov] != 0, s.hls = v_[kHls] != 0, s.lls = v_[kLls] != 0;
        return s;
    }
    void move(double target, Done done) override {
        auto shared = std::make_shared<Done>(std::move(done));
        std::weak_ptr<int> alive = life_;
        ch_[kVal]->put(target, [this, alive, target, shared](const ca::Result& r) {
            if (alive.expired()) return;
            // The readback as it is now, not as the last monitor said: a monitor may trail the
            // put-callback's reply.
            const bool put_ok = r.ok();
            ch_[kRbv]->get([this, alive, put_ok, target, shared](const ca::Result& g) {
                if (alive.expired()) return;
                const double rbv = g.ok() ? g.value.as_double() : v_[kRbv];
                judge(name_, put_ok && g.ok(), rbv, target, std::max(v_[kRdbd], std::fabs(v_[kMres])), shared);
            });
        });
    }
    void stop() override { ch_[kStop]->put(1.0); }

private:
    enum { kVal, kRbv, kHlm, kLlm, kRdbd, kMres, kDmov, kHls, kLls, kStop, kCount };
    std::string name_;
    std::shared_ptr<int> life_; // callbacks check it: none runs into a destroyed port
    std::shared_ptr<ca::Channel> ch_[kCount];
    std::shared_ptr<ca::Monitor> mon_[kCount];
    double v_[kCount] = {};
    bool have_[kCount] = {};
};

class LocalReader final : public PvReader {
public:
    LocalReader(pv::Database& db, const std::string& name, const pv::Address& a) : db_(db), name_(name), a_(a) {}
    const std::string& name() const override { return name_; }
    bool read(double& v) const override { return db_.readable_as(a_, pv::Prim::Double) && db_.get(a_, pv::Prim::Double, &v, 1) == 1; }

private:
    pv::Database& db_;
    std::string name_;
    pv::Address a_;
};

class CaReader final : public PvReader {
public:
    CaReader(ca::Client& client, const std::string& name) : name_(name), life_(std::make_shared<int>(0)) {
        ch_ = client.channel(name);
        std::weak_ptr<int> alive = life_;
        mon_ = ch_->monitor(pv::kDbeValue | pv::kDbeAlarm, [this, alive](const ca::Result& r) {
            if (alive.expired()) return;
            if (r.ok()) v_ = r.value.as_double(), have_ = true;
        });
    }
    const std::string& name() const override { return name_; }
    bool read(double& v) const override {
        if (!ch_->connected() || !have_) return false;
        v = v_;
        return true;
    }

private:
    std::string name_;
    std::shared_ptr<int> life_;
    std::shared_ptr<ca::Channel> ch_;
    std::shared_ptr<ca::Monitor> mon_;
    double v_ = 0;
    bool have_ = false;
};

class LocalWriter final : public PvWriter {
public:
    LocalWriter(pv::Database& db, const std::string& name, const pv::Address& a) : db_(db), name_(name), a_(a) {}
    const std::string& name() const override { return name_; }
    void put(double v, bool wait, MotorPort::Done done) override {
        auto shared = std::make_shared<MotorPort::Done>(std::move(done));
        auto fire = [shared, this](pv::PutStatus s) {
            if (!*shared) return;
            const MotorPort::Done d = std::move(*shared);
            *shared = nullptr;
            d(s == pv::PutStatus::Ok, s == pv::PutStatus::Ok ? std::string() : "the put to " + name_ + " failed");
        };
        const pv::PutStatus st = db_.put(a_, pv::Prim::Double, &v, 1, wait ? pv::PutCallback(fire) : pv::PutCallback());
        if (st != pv::PutStatus::Ok || !wait) fire(st);
    }

private:
    pv::Database& db_;
    std::string name_;
    pv::Address a_;
};

class CaWriter final : public PvWriter {
public:
    CaWriter(ca::Client& client, const std::string& name) : name_(name), ch_(client.channel(name)), life_(std::make_shared<int>(0)) {}
    const std::string& name() const override { return name_; }
    void put(double v, bool wait, MotorPort::Done done) override {
        if (!wait) {
            const bool ok = ch_->put(v);
            return done(ok, ok ? std::string() : name_ + " is not connected");
        }
        std::weak_ptr<int> alive = life_;
        ch_->put(v, [this, alive, done](const ca::Result& r) {
            if (alive.expired()) return;
            done(r.ok(), r.ok() ? std::string() : "the put to " + name_ + " failed: " + r.message);
        });
    }

private:
    std::string name_;
    std::shared_ptr<ca::Channel> ch_;
    std::shared_ptr<int> life_;
};

} // namespace

std::unique_ptr<PvWriter> make_local_writer(pv::Database& db, const std::string& channel) {
    pv::Address a;
    if (!db.resolve(channel, a)) return nullptr;
    return std::make_unique<LocalWriter>(db, channel, a);
}
std::unique_ptr<PvWriter> make_ca_writer(ca::Client& client, const std::string& channel) {
    return std::make_unique<CaWriter>(client, channel);
}

std::unique_ptr<MotorPort> make_local_motor(pv::Database& db, const std::string& record) { return std::make_unique<LocalMotor>(db, record); }
std::unique_ptr<MotorPort> make_ca_motor(ca::Client& client, const std::string& record) { return std::make_unique<CaMotor>(client, record); }

std::unique_ptr<PvReader> make_local_reader(pv::Database& db, const std::string& channel) {
    pv::Address a;
    if (!db.resolve(channel, a)) return nullptr;
    return std::make_unique<LocalReader>(db, channel, a);
}
std::unique_ptr<PvReader> make_ca_reader(ca::Client& client, const std::string& channel) {
    return std::make_unique<CaReader>(client, channel);
}

} // namespace beamctl::automation
