#include "feedback/feedback_module.hpp"

#include "core/error.hpp"
#include "pv/database.hpp"
#include "pv/db_file.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace beamctl::feedback {
namespace {

std::string at(const std::string& where) { return where.empty() ? std::string("the IOC file") : where; }

std::string num(double v) {
    char b[64];
    std::snprintf(b, sizeof b, "%.17g", v);
    return b;
}

} // namespace

// The Triggers stage's feedback part: every loop, in the order of `feedback:`.
class FeedbackModule::Stage : public rt::Stage {
public:
    explicit Stage(FeedbackModule& f) : f_(f) {}
    const char* name() const noexcept override { return "feedback"; }
    void run(const rt::CycleInfo& c) noexcept override {
        for (auto& lp : f_.loops_) {
            Loop& l = *lp;
            const bool valid = (!l.in_ok.bound() || l.in_ok.get() != 0) && (!l.out_ok.bound() || l.out_ok.get() != 0);
            const double x = l.inp.read(c.t_ns) * l.cfg.input_scale + l.cfg.input_offset;
            double out = 0;
            if (l.loop->cycle(valid, x, l.read_output(), out)) l.write_output(out);
        }
    }

private:
    FeedbackModule& f_;
};

// "Fast Epid" device support: the record's exchange with its loop.
class FeedbackModule::Device : public FastEpidDevice {
public:
    explicit Device(Loop& l) : l_(l) {}
    State exchange(const Params& p) override { return l_.loop->exchange(p); }
    std::string describe() const override { return "fast EPID loop " + l_.cfg.name + ": " + l_.cfg.input + " -> " + l_.cfg.output; }

private:
    Loop& l_;
};

double FeedbackModule::Loop::read_output() const noexcept {
    double raw;
    if (out_float_bits == 32) {
        const uint32_t bits = uint32_t(out.get_raw());
        float f;
        std::memcpy(&f, &bits, sizeof f);
        raw = f;
    } else if (out_float_bits == 64) {
        const uint64_t bits = out.get_raw();
        std::memcpy(&raw, &bits, sizeof raw);
    } else {
        raw = double(out.get());
    }
    return raw * cfg.output_scale + cfg.output_offset;
}

void FeedbackModule::Loop::write_output(double v) const noexcept {
    const double raw = (v - cfg.output_offset) / cfg.output_scale;
    if (out_float_bits == 32) {
        const float f = float(raw);
        uint32_t bits;
        std::memcpy(&bits, &f, sizeof bits);
        out.set(int64_t(bits));
    } else if (out_float_bits == 64) {
        int64_t bits;
        std::memcpy(&bits, &raw, sizeof bits);
        out.set(bits);
    } else {
        double r = std::nearbyint(raw);
        if (!(r >= double(out_min))) r = double(out_min); // also NaN
        if (r > double(out_max)) r = double(out_max);
        out.set(int64_t(r));
    }
}

// One loop's record: synApps' epid with the loop's initial parameters.
const module::PvTable& FeedbackModule::table() {
    static const module::PvTable t{"feedback loop",
                                   {{"", "epid", "",
                                     {{"DTYP", "Fast Epid"}, {"INP", "@$(NAME)"}, {"SCAN", "$(SCAN)"}, {"DESC", "$(DESC)"},
                                      {"KP", "$(KP)"}, {"KI", "$(KI)"}, {"KD", "$(KD)"}, {"VAL", "$(VAL)"},
                                      {"DRVH", "$(DRVH)"}, {"DRVL", "$(DRVL)"}, {"DT", "$(DT)"}, {"FBON", "$(FBON)"},
                                      {"HOPR", "$(HOPR)"}, {"LOPR", "$(LOPR)"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)"}}}}};
    return t;
}

FeedbackModule::FeedbackModule(std::vector<config::FeedbackEntry> section, module::BuildContext& ctx) : reg_(ctx.signals) {
    pv::DbFile f;
    for (config::FeedbackEntry& e : section) {
        auto l = std::make_unique<Loop>();
        // the output: a bus output entry, this loop its one writer
        int bit = -1;
        const registry::Signal* s = reg_.find_with_bit(e.output, bit);
        if (!s || s->owner_kind != registry::OwnerKind::Bus || s->direction != registry::Direction::Output || bit >= 0 || s->type == "BOOL")
            throw Error(SB() << at(e.output_where) << ": feedback " << e.name << " output: '" << e.output
                             << "' is not an analog output entry of a bus (ec<m>.s<k>.<entry>; `beamctl signals` lists them)");
        std::string why;
        if (!reg_.claim(s->name, "feedback " + e.name, why)) throw Error(SB() << at(e.output_where) << ": feedback " << e.name << " output: " << why);
        l->out_float_bits = registry::datatype_float_bits(s->type);
        int in_bit = -1; // the input exists (bind() then resolves it in the cycle)
        if (!reg_.find_with_bit(e.input, in_bit))
            throw Error(SB() << at(e.input_where) << ": feedback " << e.name << " input: no signal '" << e.input
                             << "' in this IOC (`beamctl signals` lists them)");
        const module::PvInstance in{ctx.prefix + e.name, "",
                                    {{"NAME", e.name}, {"SCAN", e.scan}, {"DESC", e.desc.substr(0, 40)},
                                     {"KP", num(e.kp)}, {"KI", num(e.ki)}, {"KD", num(e.kd)}, {"VAL", num(e.val)},
                                     {"DRVH", num(e.drvh)}, {"DRVL", num(e.drvl)}, {"DT", num(e.dt)}, {"FBON", e.fbon ? "On" : "Off"},
                                     {"HOPR", num(e.hopr)}, {"LOPR", num(e.lopr)}, {"PREC", std::to_string(e.prec)}, {"EGU", e.egu.substr(0, 15)}}};
        pv::merge_db(f, make_records(table(), in, reg_));
        l->cfg = std::move(e);
        loops_.push_back(std::move(l));
    }
    if (!f.records.empty()) ctx.db.load(f);
}

FeedbackModule::~FeedbackModule() = default;

void FeedbackModule::bind(module::BindContext& ctx) {
    rt::Engine& engine = ctx.cycle;
    motion::AxisGroup* axes = ctx.axes;
    if (loops_.empty()) return;
    const double cycle_s = double(engine.period_ns()) * 1e-9;
    for (auto& lp : loops_) {
        Loop& l = *lp;
        const config::FeedbackEntry& e = l.cfg;
        std::string why;
        l.inp = module::resolve_value(reg_, axes, e.input, why);
        if (l.inp.kind == module::ValueSource::Kind::None || l.inp.kind == module::ValueSource::Kind::Time)
            throw Error(SB() << at(e.input_where) << ": feedback " << e.name << " input: "
                             << (why.empty() ? std::string("'time' is not a controlled value") : why));
        l.out = reg_.bind(e.output, why);
        if (!l.out.bound()) throw Error(SB() << at(e.output_where) << ": feedback " << e.name << " output: " << why);
        if (!l.out_float_bits) {
            const int bits = l.out.bits;
            l.out_min = l.out.is_signed ? -(int64_t(1) << (bits - 1)) : 0;
            l.out_max = l.out.is_signed ? (int64_t(1) << (bits - 1)) - 1 : int64_t((uint64_t(1) << std::min(bits, 63)) - 1);
        }
        auto ok_of = [&](int bus) {
            std::string w;
            return bus >= 0 ? reg_.bind(std::string(SB() << "ec" << bus << ".masterstatus"), w) : registry::BoundSignal{};
        };
        l.in_ok = ok_of(l.inp.bus);
        int out_bus = -1;
        std::sscanf(e.output.c_str(), "ec%d.", &out_bus);
        l.out_ok = ok_of(out_bus);
        FastEpidLoop::Params p;
        p.setpoint = e.val, p.kp = e.kp, p.ki = e.ki, p.kd = e.kd, p.drvh = e.drvh, p.drvl = e.drvl, p.dt = e.dt, p.fbon = e.fbon;
        l.loop = std::make_unique<FastEpidLoop>(cycle_s, p);
    }
    stage_ = std::make_unique<Stage>(*this);
    engine.add_stage(rt::StageOrder::Triggers, *stage_);
}

bool FeedbackModule::owns_device(std::string_view record_type, std::string_view) const { return record_type == "epid"; }

std::unique_ptr<pv::LinkDevice> FeedbackModule::make_device(const module::DeviceRequest& rq, std::string& why) {
    const std::string_view name = rq.address;
    for (auto& lp : loops_)
        if (lp->cfg.name == name) {
            if (!lp->loop) {
                why = "feedback " + lp->cfg.name + " is not bound to the cycle";
                return nullptr;
            }
            return std::make_unique<Device>(*lp);
        }
    std::string have;
    for (auto& lp : loops_) have += (have.empty() ? "" : ", ") + lp->cfg.name;
    why = SB() << "no feedback loop '" << name << "' in this IOC (feedback: in the IOC file" << (have.empty() ? std::string(")") : "; it has " + have + ")");
    return nullptr;
}

} // namespace beamctl::feedback
