#include "ioc/flyscan.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "ioc/pv_util.hpp"
#include "pv/db_file.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace beamctl::ioc {
namespace {

log::Logger lg("flyscan");

std::string at(const std::string& where) { return where.empty() ? std::string("the IOC file") : where; }

// "capture_%04d.h5" with the capture number; a name without a %d conversion is used as it is.
std::string format_name(const std::string& tmpl, uint64_t n) {
    auto pct = tmpl.find('%');
    if (pct == std::string::npos) return tmpl;
    auto d = tmpl.find('d', pct);
    if (d == std::string::npos || tmpl.find_first_not_of("0123456789", pct + 1) != d) return tmpl;
    char buf[512];
    std::snprintf(buf, sizeof buf, "%s%0*llu%s", tmpl.substr(0, pct).c_str(),
                  d > pct + 1 ? std::atoi(tmpl.substr(pct + 1, d - pct - 1).c_str()) : 1, static_cast<unsigned long long>(n),
                  tmpl.substr(d + 1).c_str());
    return buf;
}

std::string join(const std::vector<std::string>& v) {
    std::string s;
    for (const std::string& x : v) s += (s.empty() ? "" : ", ") + x;
    return s;
}

// A UINT64 bus entry (a DC time stamp, ns): captured exactly, value mode only.
bool is_uint64_entry(const registry::Signal* s) {
    return s && s->owner_kind == registry::OwnerKind::Bus && (s->type == "UINT64" || s->type == "ULINT");
}

} // namespace

// The Triggers stage: the blocks in id order, then the capture.
class IocFlyScan::Stage : public rt::Stage {
public:
    explicit Stage(IocFlyScan& f) : f_(f), in_(f.fields_.size()) {}
    const char* name() const noexcept override { return "flyscan"; }
    void run(const rt::CycleInfo& c) noexcept override {
        for (auto& bp : f_.blocks_) {
            Block& b = *bp;
            Block::Cmd cmd;
            while (b.cmds.pop(cmd)) { // PV puts: into the cells, as a PLC's writes
                to_cells(cmd, b.cell);
                if (cmd.inp.kind != b.inp.kind || cmd.inp.cell != b.inp.cell || cmd.inp.entry.bit_offset != b.inp.entry.bit_offset) {
                    if (b.timed) b.timed->reset(); // the predictions start over on the new input
                    if (b.over) b.over->reset();
                }
                b.inp = cmd.inp;
            }
            // the cells (PV puts and PLC code) -> the block; nonsense is clamped, never taken
            double* k = b.cell;
            daq::PcompParams& q = b.pc.params;
            q.start = k[Block::Start];
            q.step = k[Block::Step];
            q.width = k[Block::Width];
            q.pre_start = k[Block::PreStart] > 0 ? k[Block::PreStart] : 0;
            q.pulses = k[Block::Pulses] > 0 && k[Block::Pulses] < 4294967295.0 ? uint32_t(k[Block::Pulses]) : 0;
            q.relative = k[Block::Relative] != 0;
            q.dir = k[Block::Dir] >= 2 ? daq::PcompDir::Either : k[Block::Dir] >= 1 ? daq::PcompDir::Negative : daq::PcompDir::Positive;
            const double x = b.inp.read(c.t_ns);
            const bool out = b.pc.step(k[Block::Enable] != 0, x);
            if (b.over) {
                if (const uint64_t dc = b.bus->dc_time()) {
                    const uint64_t x_ns = b.inp.kind == module::ValueSource::Kind::Time ? dc + c.period_ns : dc;
                    const unsigned n = unsigned(b.samples.size());
                    b.over->step(q, k[Block::Enable] != 0, x, x_ns, dc, c.period_ns, n);
                    for (unsigned i = 0; i < n; ++i) b.samples[i].set(b.over->sample(i) ? b.cfg.analog_high : b.cfg.analog_low);
                    b.st_timed.store(b.over->edges(), std::memory_order_relaxed);
                }
            } else if (!b.samples.empty()) {
                b.samples[0].set(out ? b.cfg.analog_high : b.cfg.analog_low);
            } else if (!b.timed) {
                b.out.set(out ? 1 : 0); // unbound: nothing
            } else if (const uint64_t dc = b.bus->dc_time()) { // no DC time yet: nothing to time against
                const uint64_t x_ns = b.inp.kind == module::ValueSource::Kind::Time ? dc + c.period_ns : dc;
                b.timed->step(q, k[Block::Enable] != 0, x, x_ns, dc, c.period_ns);
                b.start_time.set(int64_t(b.timed->start_time()));
                b.out.set(b.timed->level() ? 1 : 0);
                b.activate.set(b.timed->activate());
                b.st_timed.store(b.timed->scheduled(), std::memory_order_relaxed);
                b.st_late.store(b.timed->late(), std::memory_order_relaxed);
            }
            k[Block::Out] = out;
            k[Block::Active] = b.pc.active();
            k[Block::Produced] = b.pc.produced();
            k[Block::Health] = double(b.pc.health());
            k[Block::State] = double(b.pc.state());
            for (int i = 0; i < Block::kParams; ++i) b.st_param[i].store(k[i], std::memory_order_relaxed);
            b.st_out.store(out, std::memory_order_relaxed);
            b.st_active.store(b.pc.active(), std::memory_order_relaxed);
            b.st_produced.store(b.pc.produced(), std::memory_order_relaxed);
            b.st_health.store(uint32_t(b.pc.health()), std::memory_order_relaxed);
            b.st_state.store(uint32_t(b.pc.state()), std::memory_order_relaxed);
            b.st_posn.store(x, std::memory_order_relaxed);
        }
        if (!f_.capture_) return;
        for (std::size_t i = 0; i < in_.size(); ++i) in_[i] = f_.fields_[i].read(c.t_ns);
        bool trigger = false;
        uint64_t t = c.t_ns;
        for (Trigger& tr : f_.triggers_) {
            if (tr.cycle) {
                trigger = true;
            } else if (tr.block >= 0) {
                const daq::Pcomp& pc = f_.blocks_[std::size_t(tr.block)]->pc;
                if (pc.rose()) {
                    // the edge's interpolated time, between the previous cycle's sample and this one's
                    uint64_t edge = c.t_ns - uint64_t(std::llround((1.0 - pc.edge_fraction()) * double(c.period_ns)));
                    t = trigger ? std::min(t, edge) : edge;
                    trigger = true;
                }
            } else {
                const bool level = tr.sig.read(c.t_ns) != 0;
                trigger = trigger || (level && !tr.level);
                tr.level = level;
            }
        }
        const bool gate = f_.gate_.kind == module::ValueSource::Kind::None || f_.gate_.read(c.t_ns) != 0;
        f_.capture_->sample(c.cycle, c.t_ns, in_.data(), gate, trigger, t);
        // the next cycle's appends belong to the capture running now (none after a DISARM)
        const uint64_t running = f_.capture_->armed() ? f_.capture_->capture() : 0;
        for (daq::DataStorage* ds : f_.taps_) ds->tap_next(c.cycle + 1, c.t_ns + c.period_ns, running);
    }

private:
    IocFlyScan& f_;
    std::vector<double> in_;
};

IocFlyScan::IocFlyScan(const config::IocConfig& cfg, registry::Registry& reg, pv::Database& db, const IocMemMaps* memmaps)
    : cfg_(cfg), reg_(reg), db_(db), memmaps_(memmaps) {
    pv::DbFile f;
    auto text = [](const std::string& name, const char* nelm) {
        return record("waveform", name, {{"FTVL", "CHAR"}, {"NELM", nelm}});
    };
    for (const config::PcompEntry& e : cfg.pcomp) {
        auto b = std::make_unique<Block>();
        b->cfg = e;
        b->pc.params = daq::PcompParams{e.pre_start, e.start, e.width, e.step, e.pulses, e.relative, daq::PcompDir(e.dir)};
        b->want.params = b->pc.params;
        b->want.enable = e.enable;
        to_cells(b->want, b->cell); // a configured ENABLE is a rising edge in the first cycle
        for (int i = 0; i < Block::kParams; ++i) b->seen_param[i] = b->cell[i];
        std::string owner = SB() << "pcomp" << e.id;
        for (const char* item : {"out", "active", "produced"}) {
            registry::Signal s;
            s.name = owner + "." + item;
            s.type = "LREAL";
            s.direction = registry::Direction::Input;
            s.owner_kind = registry::OwnerKind::Engine;
            s.owner = owner;
            s.pv = SB() << cfg.prefix << "PCOMP" << e.id << ":" << (std::string(item) == "out" ? "OUT" : std::string(item) == "active" ? "ACTIVE" : "PRODUCED");
            reg.declare(std::move(s));
        }
        std::string p = SB() << cfg.prefix << "PCOMP" << e.id << ":";
        auto num = [](double v) { return std::string(SB() << v); };
        std::string egu = e.egu.substr(0, 15);
        f.records.push_back(record("bo", p + "ENABLE", {{"DESC", e.desc.substr(0, 40)}, {"ZNAM", "0"}, {"ONAM", "1"}, {"VAL", e.enable ? "1" : "0"}}));
        f.records.push_back(record("stringout", p + "INP", {{"DESC", "engine signal compared"}, {"VAL", e.input.substr(0, 39)}}));
        for (auto [name, v] : {std::pair<const char*, double>{"PRE_START", e.pre_start}, {"START", e.start}, {"WIDTH", e.width}, {"STEP", e.step}})
            f.records.push_back(record("ao", p + name, {{"VAL", num(v)}, {"PREC", "4"}, {"EGU", egu}}));
        f.records.push_back(record("longout", p + "PULSES", {{"VAL", std::to_string(e.pulses)}, {"DRVL", "0"}, {"DRVH", "2147483647"}, {"DESC", "0: unlimited"}}));
        f.records.push_back(record("bo", p + "RELATIVE", {{"ZNAM", "Absolute"}, {"ONAM", "Relative"}, {"VAL", e.relative ? "1" : "0"}}));
        f.records.push_back(record("mbbo", p + "DIR", {{"ZRST", "Positive"}, {"ONST", "Negative"}, {"TWST", "Either"}, {"VAL", std::to_string(e.dir)}}));
        f.records.push_back(record("bi", p + "ACTIVE", {{"ZNAM", "0"}, {"ONAM", "1"}}));
        f.records.push_back(record("bi", p + "OUT", {{"ZNAM", "0"}, {"ONAM", "1"}}));
        f.records.push_back(record("longin", p + "PRODUCED", {{"DESC", "pulses since enable"}}));
        f.records.push_back(record("mbbi", p + "HEALTH", {{"ZRST", "OK"}, {"ONST", "Jumped more than STEP"}, {"TWST", "Cannot guess DIR"},
                                                          {"ONSV", "MAJOR"}, {"TWSV", "MAJOR"}}));
        f.records.push_back(record("mbbi", p + "STATE", {{"ZRST", "WAIT_ENABLE"}, {"ONST", "WAIT_DIR"}, {"TWST", "WAIT_PRE_START"},
                                                         {"THST", "WAIT_RISING"}, {"FRST", "WAIT_FALLING"}}));
        f.records.push_back(record("ai", p + "POSN", {{"DESC", "INP now"}, {"PREC", "4"}, {"EGU", egu}}));
        f.records.push_back(record("longin", p + "TIMED", {{"DESC", "edges sent timestamped"}}));
        f.records.push_back(record("longin", p + "LATE", {{"DESC", "timestamped edges too late"}, {"HIGH", "1"}, {"HSV", "MINOR"}}));
        blocks_.push_back(std::move(b));
    }
    if (cfg.capture) {
        const config::CaptureEntry& c = *cfg.capture;
        std::string p = cfg.prefix + "PCAP:";
        f.records.push_back(record("bo", p + "ARM", {{"ZNAM", "0"}, {"ONAM", "1"}, {"DESC", "1: start a capture"}}));
        f.records.push_back(record("bo", p + "DISARM", {{"ZNAM", "0"}, {"ONAM", "1"}, {"DESC", "1: end the capture"}}));
        f.records.push_back(record("bi", p + "ACTIVE", {{"ZNAM", "0"}, {"ONAM", "1"}}));
        f.records.push_back(text(p + "FILE_PATH", "256"));
        f.records.push_back(text(p + "FILE_NAME", "256"));
        f.records.push_back(text(p + "FULL_FILE_NAME", "512"));
        f.records.push_back(text(p + "STATUS", "256"));
        f.records.push_back(record("bi", p + "ERROR", {{"ZNAM", "OK"}, {"ONAM", "Error"}, {"OSV", "MAJOR"}}));
        f.records.push_back(record("longin", p + "CAPTURE", {{"DESC", "number of the last capture"}}));
        f.records.push_back(record("longin", p + "ROWS_CAPTURED", {{"DESC", "rows the cycle captured"}}));
        f.records.push_back(record("longin", p + "ROWS_WRITTEN", {{"DESC", "rows in the file"}}));
        f.records.push_back(record("longin", p + "ROWS_DROPPED", {{"DESC", "rows lost: ring full"}, {"HIGH", "1"}, {"HSV", "MAJOR"}}));
        f.records.push_back(record("longin", p + "FILES", {{"DESC", "files completed"}}));
        std::string nelm = std::to_string(std::max<std::size_t>(c.last_rows, 1));
        f.records.push_back(record("waveform", p + "LAST:CYCLE", {{"FTVL", "DOUBLE"}, {"NELM", nelm}, {"DESC", "cycles of the last rows"}}));
        for (const config::CaptureField& cf : c.fields) {
            const std::vector<std::string>* samples = samples_of(cf.signal); // n values a row
            const std::string n = samples ? std::to_string(std::max<std::size_t>(c.last_rows, 1) * samples->size()) : nelm;
            for (const std::string& m : cf.modes) {
                std::string col = m == "value" ? cf.name : cf.name + "_" + m;
                columns_.push_back(col);
                f.records.push_back(record("waveform", p + "LAST:" + col,
                                           {{"FTVL", "DOUBLE"}, {"NELM", n}, {"EGU", cf.units.substr(0, 15)}, {"PREC", "6"}}));
            }
        }
    }
    db_.load(f);
    check_names();
    auto find = [&](const std::string& name) {
        pv::Record* r = db_.find(name);
        if (!r) throw Error(SB() << "flyscan: no record " << name);
        return r;
    };
    for (auto& bp : blocks_) {
        Block& b = *bp;
        std::string p = SB() << cfg.prefix << "PCOMP" << b.cfg.id << ":";
        b.enable_r = find(p + "ENABLE");
        b.inp_r = find(p + "INP");
        b.pre_start = find(p + "PRE_START");
        b.start = find(p + "START");
        b.width = find(p + "WIDTH");
        b.step = find(p + "STEP");
        b.pulses = find(p + "PULSES");
        b.relative = find(p + "RELATIVE");
        b.dir = find(p + "DIR");
        b.active = find(p + "ACTIVE");
        b.out_r = find(p + "OUT");
        b.produced = find(p + "PRODUCED");
        b.health = find(p + "HEALTH");
        b.state = find(p + "STATE");
        b.posn = find(p + "POSN");
        b.timed_r = find(p + "TIMED");
        b.late = find(p + "LATE");
        for (pv::Record* r : {b.active, b.out_r, b.produced, b.health, b.state, b.posn, b.timed_r, b.late}) r->val_read_only = true;
        Block* self = &b;
        auto param = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) != "VAL") return pv::PutStatus::Ok;
            double v = get_value(r);
            Block& k = *self;
            daq::PcompParams& q = k.want.params;
            if (&r == k.enable_r) k.want.enable = v != 0;
            else if (&r == k.pre_start) {
                if (v < 0) {
                    LOG_WARN(lg, r.name() << ": " << v << " refused: PRE_START must be >= 0");
                    return pv::PutStatus::Failed;
                }
                q.pre_start = v;
            } else if (&r == k.start) q.start = v;
            else if (&r == k.width) q.width = v;
            else if (&r == k.step) q.step = v;
            else if (&r == k.pulses) q.pulses = uint32_t(std::max(0.0, v));
            else if (&r == k.relative) q.relative = v != 0;
            else if (&r == k.dir) {
                if (v < 0 || v > 2) return pv::PutStatus::Failed;
                q.dir = daq::PcompDir(int(v));
            }
            return send(k) ? pv::PutStatus::Ok : pv::PutStatus::Failed;
        };
        for (pv::Record* r : {b.enable_r, b.pre_start, b.start, b.width, b.step, b.pulses, b.relative, b.dir}) r->put_hook = param;
        b.inp_r->put_hook = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) != "VAL") return pv::PutStatus::Ok;
            char buf[pv::kStringSize] = {};
            pv::Elements e = r.elements(fd);
            pv::get_element(r, fd, e, 0, pv::Prim::String, buf);
            std::string why;
            module::ValueSource src = resolve(buf, why);
            if (src.kind == module::ValueSource::Kind::None) {
                LOG_WARN(lg, r.name() << ": '" << buf << "' refused: " << why);
                return pv::PutStatus::Failed;
            }
            if (self->want.enable || self->st_active.load(std::memory_order_relaxed)) {
                LOG_WARN(lg, r.name() << ": '" << buf << "' refused: disable the block first");
                return pv::PutStatus::Failed;
            }
            self->want.inp = src;
            return send(*self) ? pv::PutStatus::Ok : pv::PutStatus::Failed;
        };
    }
    if (cfg.capture) {
        std::string p = cfg.prefix + "PCAP:";
        arm_ = find(p + "ARM");
        disarm_ = find(p + "DISARM");
        cap_active_ = find(p + "ACTIVE");
        file_path_ = find(p + "FILE_PATH");
        file_name_ = find(p + "FILE_NAME");
        full_name_ = find(p + "FULL_FILE_NAME");
        status_ = find(p + "STATUS");
        error_ = find(p + "ERROR");
        capture_no_ = find(p + "CAPTURE");
        rows_captured_ = find(p + "ROWS_CAPTURED");
        rows_written_ = find(p + "ROWS_WRITTEN");
        rows_dropped_ = find(p + "ROWS_DROPPED");
        files_ = find(p + "FILES");
        last_cycle_ = find(p + "LAST:CYCLE");
        for (const std::string& col : columns_) last_.push_back({find(p + "LAST:" + col)});
        for (pv::Record* r : {cap_active_, full_name_, status_, error_, capture_no_, rows_captured_, rows_written_, rows_dropped_, files_, last_cycle_})
            r->val_read_only = true;
        for (LastPv& l : last_) l.r->val_read_only = true;
        arm_->put_hook = [this](pv::Record& r, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) != "VAL" || get_value(r) == 0) return pv::PutStatus::Ok;
            return arm() ? pv::PutStatus::Ok : pv::PutStatus::Failed;
        };
        disarm_->put_hook = [this](pv::Record& r, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) != "VAL" || get_value(r) == 0) return pv::PutStatus::Ok;
            stop();
            return pv::PutStatus::Ok;
        };
    }
}

IocFlyScan::~IocFlyScan() = default;

// Every name of `pcomp:` and `capture:` exists (what `beamctl check` can say without bring-up;
// bind() then resolves each to its place).
void IocFlyScan::check_names() {
    auto known = [&](const std::string& name, std::string& why) {
        if (name == "time") return true;
        for (const auto& b : blocks_) {
            std::string p = SB() << "pcomp" << b->cfg.id << ".";
            if (name.rfind(p, 0) == 0) {
                std::string item = name.substr(p.size());
                if (item == "out" || item == "active" || item == "produced" || item == "rose") return true;
                why = SB() << "'" << name << "': a block has out, active, produced and rose";
                return false;
            }
        }
        int bit = -1;
        const registry::Signal* s = reg_.find_with_bit(name, bit);
        if (!s) why = SB() << "no signal '" << name << "' in this IOC (`beamctl signals` lists them; or time)";
        else if (s->loop_only) why = SB() << "'" << name << "' is a value of the IOC loop, not of the cycle";
        else if (s->owner_kind != registry::OwnerKind::Axis && s->owner_kind != registry::OwnerKind::Bus)
            why = SB() << "'" << name << "' is a signal of " << s->owner << "; position compare and capture read bus entries, axis variables, pcomp<n>.* and time";
        else return true;
        return false;
    };
    std::string why;
    for (const auto& b : blocks_) {
        if (!known(b->cfg.input, why)) throw Error(SB() << at(b->cfg.input_where) << ": pcomp" << b->cfg.id << " input: " << why);
        if (b->cfg.output.empty()) continue;
        int bit = -1;
        const registry::Signal* s = reg_.find_with_bit(b->cfg.output, bit);
        if (!s || s->owner_kind != registry::OwnerKind::Bus || s->direction != registry::Direction::Output)
            throw Error(SB() << at(b->cfg.output_where) << ": pcomp" << b->cfg.id << " output: '" << b->cfg.output
                             << "' is not an output entry of a bus (ec<m>.s<k>.<entry>[.<bit>])");
        // the block is the output's one writer; of an EL2252 channel also of its slave's startTime
        // and activate (one block per EL2252)
        if (!reg_.claim(s->name, SB() << "pcomp" << b->cfg.id, why))
            throw Error(SB() << at(b->cfg.output_where) << ": pcomp" << b->cfg.id << " output: " << why);
        if (s->type != "BOOL" && bit < 0) {
            // an analog output: its value is analog_high / analog_low; an EL4732 channel's first
            // sample (<entry>_1) takes the channel's n samples of the cycle
            b->sample_names = {s->name};
            const std::size_t us = s->name.rfind("_1");
            if (us != std::string::npos && us + 2 == s->name.size())
                for (int k = 2; k <= 1000; ++k) {
                    const std::string n = s->name.substr(0, us + 1) + std::to_string(k);
                    const registry::Signal* more = reg_.find(n);
                    if (!more || more->direction != registry::Direction::Output) break;
                    if (!reg_.claim(n, SB() << "pcomp" << b->cfg.id << " (oversampled output " << s->name << ")", why))
                        throw Error(SB() << at(b->cfg.output_where) << ": pcomp" << b->cfg.id << " output: " << why);
                    b->sample_names.push_back(n);
                }
            continue;
        }
        const std::size_t dot = s->name.find('.', s->name.find('.') + 1);
        const std::string slave = s->name.substr(0, dot + 1); // "ec0.s4."
        const registry::Signal* st = reg_.find(slave + "startTime");
        const registry::Signal* act = reg_.find(slave + "activate");
        if (dot != std::string::npos && st && act && st->direction == registry::Direction::Output && st->type == "UINT64") {
            for (const registry::Signal* t : {st, act})
                if (!reg_.claim(t->name, SB() << "pcomp" << b->cfg.id << " (timestamped output " << s->name << ")", why))
                    throw Error(SB() << at(b->cfg.output_where) << ": pcomp" << b->cfg.id << " output: " << why);
            b->timed_prefix = slave;
        }
    }
    if (!cfg_.capture) return;
    const config::CaptureEntry& c = *cfg_.capture;
    for (const config::CaptureField& cf : c.fields) {
        if (const std::vector<std::string>* samples = samples_of(cf.signal)) {
            for (const std::string& m : cf.modes)
                if (m != "value")
                    throw Error(SB() << at(cf.where) << ": capture field " << cf.signal << ": a memory map (" << samples->size()
                                     << " samples a cycle) is captured as its values only, not '" << m << "'");
            if (!known(samples->front(), why)) throw Error(SB() << at(cf.where) << ": capture field " << cf.signal << ": " << why);
            continue;
        }
        if (!known(cf.signal, why)) throw Error(SB() << at(cf.where) << ": capture field: " << why);
        if (is_uint64_entry(reg_.find(cf.signal)))
            for (const std::string& m : cf.modes)
                if (m != "value")
                    throw Error(SB() << at(cf.where) << ": capture field " << cf.signal << ": a UINT64 entry (a time stamp) is captured as its value only, not '" << m << "'");
    }
    for (const std::string& t : c.triggers) {
        bool block = false;
        for (const auto& b : blocks_) block = block || t == std::string(SB() << "pcomp" << b->cfg.id);
        if (t != "cycle" && !block && !known(t, why)) throw Error(SB() << at(c.trigger_where) << ": capture trigger: " << why << " (or pcomp<n>, cycle)");
    }
    if (!c.gate.empty() && !known(c.gate, why)) throw Error(SB() << at(c.gate_where) << ": capture gate: " << why);
}

void IocFlyScan::to_cells(const Block::Cmd& c, double* k) {
    k[Block::Enable] = c.enable;
    k[Block::Start] = c.params.start;
    k[Block::Step] = c.params.step;
    k[Block::Width] = c.params.width;
    k[Block::Pulses] = c.params.pulses;
    k[Block::PreStart] = c.params.pre_start;
    k[Block::Relative] = c.params.relative;
    k[Block::Dir] = double(int(c.params.dir));
}

std::optional<plc::Binding> IocFlyScan::plc_cell(const std::string& name) {
    static_assert(std::size(daq::kPcompPlcItems) == Block::kCells && daq::kPcompPlcWritable == Block::kParams);
    const auto& names = daq::kPcompPlcItems;
    for (auto& b : blocks_) {
        std::string p = SB() << "pcomp" << b->cfg.id << ".";
        if (name.rfind(p, 0) != 0) continue;
        for (int i = 0; i < Block::kCells; ++i)
            if (name.compare(p.size(), std::string::npos, names[i]) == 0) return plc::Binding{&b->cell[i], i < Block::kParams, 1};
    }
    return std::nullopt;
}

bool IocFlyScan::send(Block& b) {
    if (b.cmds.push(b.want)) return true;
    LOG_WARN(lg, "pcomp" << b.cfg.id << ": refused, the cycle has not taken the last changes yet");
    return false;
}

module::ValueSource IocFlyScan::resolve(const std::string& name, std::string& why) const {
    module::ValueSource v;
    for (std::size_t i = 0; i < blocks_.size(); ++i) {
        std::string p = SB() << "pcomp" << blocks_[i]->cfg.id << ".";
        if (name.rfind(p, 0) != 0) continue;
        std::string item = name.substr(p.size());
        v.pcomp = &blocks_[i]->pc;
        if (item == "out") v.kind = module::ValueSource::Kind::PcompOut;
        else if (item == "active") v.kind = module::ValueSource::Kind::PcompActive;
        else if (item == "produced") v.kind = module::ValueSource::Kind::PcompProduced;
        else if (item == "rose") v.kind = module::ValueSource::Kind::PcompRose;
        else why = SB() << "'" << name << "': a block has out, active, produced and rose";
        return v;
    }
    return module::resolve_value(reg_, axes_, name, why);
}

void IocFlyScan::bind(rt::Engine& engine, motion::AxisGroup* axes, const std::vector<ethercat::Bus*>& buses,
                      const std::vector<daq::DataStorage*>& storages) {
    if (!enabled()) return;
    axes_ = axes;
    for (auto& bp : blocks_) {
        Block& b = *bp;
        std::string why;
        b.inp = resolve(b.cfg.input, why);
        if (b.inp.kind == module::ValueSource::Kind::None) throw Error(SB() << at(b.cfg.input_where) << ": pcomp" << b.cfg.id << " input: " << why);
        b.want.inp = b.inp;
        if (!b.cfg.output.empty()) {
            b.out = reg_.bind(b.cfg.output, why);
            if (!b.out.bound()) throw Error(SB() << at(b.cfg.output_where) << ": pcomp" << b.cfg.id << " output: " << why);
            if (!b.sample_names.empty()) {
                b.out = {}; // the samples instead
                for (const std::string& n : b.sample_names) {
                    b.samples.push_back(reg_.bind(n, why));
                    if (!b.samples.back().bound()) throw Error(SB() << at(b.cfg.output_where) << ": pcomp" << b.cfg.id << " output: " << why);
                }
            }
            if (!b.timed_prefix.empty() || b.samples.size() > 1) {
                for (ethercat::Bus* bus : buses)
                    if (b.cfg.output.rfind(std::string(SB() << "ec" << bus->id() << "."), 0) == 0) b.bus = bus;
                if (!b.bus || !b.bus->backend().local_master())
                    throw Error(SB() << at(b.cfg.output_where) << ": pcomp" << b.cfg.id << " output: " << b.cfg.output
                                     << " is a DC-timestamped or oversampled output; it needs a bus this IOC masters (not one behind a scanner)");
            }
            if (b.samples.size() > 1) b.over = std::make_unique<daq::OversampledPcompOutput>();
            if (!b.timed_prefix.empty()) {
                b.start_time = reg_.bind(b.timed_prefix + "startTime", why);
                b.activate = reg_.bind(b.timed_prefix + "activate", why);
                if (!b.start_time.bound() || !b.activate.bound())
                    throw Error(SB() << at(b.cfg.output_where) << ": pcomp" << b.cfg.id << " output: " << why);
                b.timed = std::make_unique<daq::TimedPcompOutput>();
            }
        }
    }
    if (cfg_.capture) {
        const config::CaptureEntry& c = *cfg_.capture;
        std::vector<daq::Capture::Column> cols;
        std::vector<daq::NexusColumn> ncols;
        for (const config::CaptureField& cf : c.fields) {
            std::string why;
            if (const std::vector<std::string>* samples = samples_of(cf.signal)) {
                // an oversampled channel: its n samples of the cycle, in time order (value only)
                last_[ncols.size()].col = cols.size();
                last_[ncols.size()].width = samples->size();
                for (const std::string& e : *samples) {
                    fields_.push_back(resolve(e, why));
                    if (fields_.back().kind == module::ValueSource::Kind::None) throw Error(SB() << at(cf.where) << ": capture field " << cf.signal << ": " << why);
                    cols.push_back({fields_.size() - 1, daq::CaptureMode::Value});
                }
                daq::NexusColumn nc{cf.name, cf.units, cf.signal, daq::to_string(daq::CaptureMode::Value)};
                nc.width = samples->size();
                ncols.push_back(std::move(nc));
                continue;
            }
            module::ValueSource v = resolve(cf.signal, why);
            if (v.kind == module::ValueSource::Kind::None) throw Error(SB() << at(cf.where) << ": capture field: " << why);
            // a UINT64 entry (DC time stamps in ns: beyond a double's 53 bits) is kept exact
            const bool u64 = v.kind == module::ValueSource::Kind::Integer && is_uint64_entry(reg_.find(cf.signal));
            if (u64) v.kind = module::ValueSource::Kind::Uint64Bits; // value only (check_names)
            fields_.push_back(v);
            for (const std::string& m : cf.modes) {
                daq::CaptureMode mode = daq::CaptureMode::Value;
                daq::parse_capture_mode(m, mode);
                last_[ncols.size()].col = cols.size();
                last_[ncols.size()].u64 = u64;
                cols.push_back({fields_.size() - 1, mode});
                ncols.push_back({m == "value" ? cf.name : cf.name + "_" + m, cf.units, cf.signal, daq::to_string(mode), u64});
            }
        }
        for (const std::string& name : c.triggers) {
            Trigger tr;
            if (name == "cycle") {
                tr.cycle = true;
            } else {
                for (std::size_t i = 0; i < blocks_.size(); ++i)
                    if (name == std::string(SB() << "pcomp" << blocks_[i]->cfg.id)) tr.block = int(i);
                if (tr.block < 0) {
                    std::string why;
                    tr.sig = resolve(name, why);
                    if (tr.sig.kind == module::ValueSource::Kind::None)
                        throw Error(SB() << at(c.trigger_where) << ": capture trigger: " << why << " (or pcomp<n>, cycle)");
                }
            }
            triggers_.push_back(tr);
        }
        if (!c.gate.empty()) {
            std::string why;
            gate_ = resolve(c.gate, why);
            if (gate_.kind == module::ValueSource::Kind::None) throw Error(SB() << at(c.gate_where) << ": capture gate: " << why);
        }
        capture_ = std::make_unique<daq::Capture>(fields_.size(), std::move(cols), c.ring_rows);
        daq::CaptureWriter::Options o;
        o.columns = std::move(ncols);
        o.nexus.title = SB() << cfg_.name << " capture";
        o.nexus.attributes = {{"ioc", cfg_.name}, {"trigger", join(c.triggers)}, {"gate", c.gate.empty() ? "always" : c.gate},
                              {"engine_rate_hz", std::string(SB() << cfg_.rate_hz)}};
        for (int id : c.storages) // checked by the configuration: each one exists
            for (daq::DataStorage* ds : storages)
                if (ds->id() == id) {
                    ds->enable_tap(c.ring_rows);
                    taps_.push_back(ds);
                    o.storages.push_back(ds);
                    o.nexus.logs.push_back({std::string(SB() << "ds" << id), "", std::string(SB() << "ds" << id << " (data storage: the values PLC code appended)")});
                }
        o.flush_s = c.flush_s;
        o.last_rows = std::max<std::size_t>(c.last_rows, 1);
        std::size_t widest = 1;
        for (const LastPv& l : last_) widest = std::max(widest, l.width);
        scratch_.reserve(o.last_rows * widest);
        o.log = [](bool error, const std::string& m) {
            if (error) LOG_ERR(lg, m);
            else LOG_INFO(lg, m);
        };
        writer_ = std::make_unique<daq::CaptureWriter>(*capture_, std::move(o));
        if (text(file_path_).empty()) set_text(file_path_, c.file_path);
        if (text(file_name_).empty()) set_text(file_name_, c.file_name);
    }
    stage_ = std::make_unique<Stage>(*this);
    engine.add_stage(rt::StageOrder::Triggers, *stage_);
}

namespace {
// Device support "beamctl" on pcomp<n>.out, .active, .produced: the block's state as the cycle last
// published it. An I/O Intr record on .out is processed for every pulse, one that rose and fell
// between two looks of the IOC loop included (PRODUCED moved). IOC loop only.
class PcompItemDevice : public pv::LinkDevice {
public:
    enum class Item { Out, Active, Produced };
    PcompItemDevice(const std::atomic<uint32_t>& value, const std::atomic<uint32_t>& produced, Item item, int bit, std::string name)
        : value_(value), produced_(produced), item_(item), bit_(bit), name_(std::move(name)) {}
    bool read(double& v) override {
        v = value();
        last_ = v;
        return true;
    }
    bool write(double) override { return false; }
    bool changed() override {
        const double v = value();
        bool c = v != last_;
        last_ = v;
        const uint32_t p = produced_.load(std::memory_order_relaxed);
        if (item_ == Item::Out && p != last_produced_) c = true;
        last_produced_ = p;
        return c;
    }
    std::string describe() const override { return name_; }

private:
    double value() const {
        const uint32_t v = value_.load(std::memory_order_relaxed);
        return bit_ >= 0 ? double((v >> bit_) & 1u) : double(v);
    }
    const std::atomic<uint32_t>& value_;
    const std::atomic<uint32_t>& produced_;
    Item item_;
    int bit_;
    std::string name_;
    double last_ = -1;
    uint32_t last_produced_ = 0;
};
} // namespace

std::unique_ptr<pv::LinkDevice> IocFlyScan::make_device(std::string_view name, int bit, bool output, std::string& why) {
    for (auto& bp : blocks_) {
        Block& b = *bp;
        const std::string owner = SB() << "pcomp" << b.cfg.id;
        if (name.size() <= owner.size() || name.compare(0, owner.size(), owner) != 0 || name[owner.size()] != '.') continue;
        const std::string_view item = name.substr(owner.size() + 1);
        using Item = PcompItemDevice::Item;
        const std::string pvs = SB() << cfg_.prefix << "PCOMP" << b.cfg.id << ":";
        if (output) {
            why = SB() << "'" << name << "' is the block's; an output link writes its parameters through " << pvs << "ENABLE, START, STEP, ... (link to those PVs)";
            return nullptr;
        }
        if ((bit > 0 && item != "produced") || bit >= 32) {
            why = SB() << "'" << name << "' is 0 or 1; it has no bit " << bit;
            return nullptr;
        }
        if (item == "out") return std::make_unique<PcompItemDevice>(b.st_out, b.st_produced, Item::Out, bit, std::string(name));
        if (item == "active") return std::make_unique<PcompItemDevice>(b.st_active, b.st_produced, Item::Active, bit, std::string(name));
        if (item == "produced") return std::make_unique<PcompItemDevice>(b.st_produced, b.st_produced, Item::Produced, bit, std::string(name));
        why = SB() << "'" << name << "': records read " << owner << ".out, .active and .produced (the parameters are the PVs " << pvs << "*)";
        return nullptr;
    }
    why = SB() << "no position-compare block for '" << name << "'";
    return nullptr;
}

const std::vector<std::string>* IocFlyScan::samples_of(const std::string& name) const {
    return memmaps_ ? memmaps_->elements(name) : nullptr;
}

std::string IocFlyScan::next_file() const {
    if (!cfg_.capture) return "";
    std::string dir = text(file_path_), name = text(file_name_);
    if (dir.empty()) dir = cfg_.capture->file_path;
    if (name.empty()) name = cfg_.capture->file_name;
    uint64_t n = (writer_ ? writer_->status().capture : 0) + 1;
    name = format_name(name, n);
    if (!dir.empty() && dir.back() != '/') dir += '/';
    return dir + name;
}

bool IocFlyScan::arm() {
    if (!writer_) return false;
    std::string path = next_file();
    if (!writer_->start(path)) {
        LOG_WARN(lg, "PCAP:ARM refused: a capture is running (" << writer_->status().file << ")");
        return false;
    }
    set_text(full_name_, path);
    return true;
}

void IocFlyScan::stop() {
    if (writer_ && writer_->status().busy) writer_->stop();
}

void IocFlyScan::set_text(pv::Record* r, const std::string& t) { ioc::set_text(db_, *r, t.substr(0, 511)); }

std::string IocFlyScan::text(pv::Record* r) const { return get_text(*r); }

void IocFlyScan::publish() {
    auto set = [&](pv::Record* r, double v) {
        if (r && (r->udf || get_value(*r) != v)) set_value(db_, *r, v, false);
    };
    for (auto& bp : blocks_) {
        Block& b = *bp;
        set(b.active, b.st_active.load(std::memory_order_relaxed));
        set(b.out_r, b.st_out.load(std::memory_order_relaxed));
        set(b.produced, b.st_produced.load(std::memory_order_relaxed));
        set(b.health, b.st_health.load(std::memory_order_relaxed));
        set(b.state, b.st_state.load(std::memory_order_relaxed));
        set(b.posn, b.st_posn.load(std::memory_order_relaxed));
        set(b.timed_r, double(b.st_timed.load(std::memory_order_relaxed)));
        set(b.late, double(b.st_late.load(std::memory_order_relaxed)));
        // parameters PLC code changed: into their PVs and into what the next put sends
        pv::Record* rec[Block::kParams] = {b.enable_r, b.start, b.step, b.width, b.pulses, b.pre_start, b.relative, b.dir};
        Block::Cmd now = b.want;
        bool changed = false;
        for (int i = 0; i < Block::kParams; ++i) {
            double v = b.st_param[i].load(std::memory_order_relaxed);
            if (v == b.seen_param[i]) continue;
            b.seen_param[i] = v;
            double cur[Block::kCells];
            to_cells(b.want, cur);
            if (cur[i] == v) continue; // our own put arriving
            changed = true;
            set(rec[i], v);
            switch (i) {
            case Block::Enable: now.enable = v != 0; break;
            case Block::Start: now.params.start = v; break;
            case Block::Step: now.params.step = v; break;
            case Block::Width: now.params.width = v; break;
            case Block::Pulses: now.params.pulses = v > 0 && v < 4294967295.0 ? uint32_t(v) : 0; break;
            case Block::PreStart: now.params.pre_start = v > 0 ? v : 0; break;
            case Block::Relative: now.params.relative = v != 0; break;
            case Block::Dir: now.params.dir = daq::PcompDir(v >= 2 ? 2 : v >= 1 ? 1 : 0); break;
            }
        }
        if (changed) b.want = now;
        // a block that ended by itself (PULSES reached, an error) is re-armed by a new ENABLE edge
    }
    if (!writer_) return;
    daq::CaptureWriter::Status s = writer_->status();
    set(cap_active_, s.busy ? 1 : 0);
    set(capture_no_, clamp_long(s.capture));
    set(rows_captured_, clamp_long(s.capture && capture_->capture() == s.capture ? capture_->pushed() : 0));
    set(rows_dropped_, clamp_long(s.dropped));
    if (s.version == status_version_) return;
    status_version_ = s.version;
    set(rows_written_, clamp_long(s.rows));
    set(files_, clamp_long(s.files));
    set(error_, s.error ? 1 : 0);
    set_text(status_, s.message);
    writer_->last_cycles(scratch_);
    set_array(db_, *last_cycle_, scratch_.data(), uint32_t(scratch_.size()));
    for (const LastPv& l : last_) {
        writer_->last_rows(l.col, scratch_, l.width);
        if (l.u64)
            for (double& d : scratch_) { // bit patterns -> their values (ns; the PV is a double)
                uint64_t raw;
                std::memcpy(&raw, &d, sizeof raw);
                d = double(raw);
            }
        set_array(db_, *l.r, scratch_.data(), uint32_t(scratch_.size()));
    }
}

} // namespace beamctl::ioc
