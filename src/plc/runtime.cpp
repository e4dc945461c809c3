#include "plc/runtime.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <ctime>
#include <limits>
#include <set>

namespace beamctl::plc {
namespace {

// ECMC error codes returned by the mc_* and ec_* functions (ecmcPLCTask.h, ecmcErrorsList.h).
constexpr double kAxisIdOutOfRange = 0x20502;   // ERROR_PLC_AXIS_ID_OUT_OF_RANGE
constexpr double kAxisObjectNull = 0x20508;     // ERROR_PLC_AXIS_OBJECT_NULL (also: no such group)
constexpr double kEcBitsOutOfRange = 0x20800;   // ERROR_PLC_EC_LIB_BITS_OUT_OF_RANGE
constexpr double kEcEntryNotValid = 0x2100E;    // ERROR_EC_ENTRY_EC_DOMAIN_ERROR: a slave it uses is out
constexpr uint32_t kEncIndexOutOfRange = 0x14326; // ECMC: encoder index out of range (mc_*_act_pos)

std::string lower(std::string_view s) {
    std::string r(s);
    for (char& c : r) c = char(std::tolower(static_cast<unsigned char>(c)));
    return r;
}

// "ax12.enc.actpos" -> (12, "enc.actpos"); false if `s` does not start with <prefix><digits>.
bool split_indexed(std::string_view s, std::string_view prefix, int& n, std::string_view& rest) {
    if (s.size() <= prefix.size() || s.substr(0, prefix.size()) != prefix) return false;
    std::size_t i = prefix.size(), j = i;
    while (j < s.size() && std::isdigit(static_cast<unsigned char>(s[j]))) ++j;
    if (j == i || j - i > 6) return false;
    n = std::stoi(std::string(s.substr(i, j - i)));
    if (j == s.size()) {
        rest = {};
        return true;
    }
    if (s[j] != '.') return false;
    rest = s.substr(j + 1);
    return true;
}

bool is_identifier(std::string_view s) {
    if (s.empty() || !(std::isalpha(static_cast<unsigned char>(s[0])) || s[0] == '_')) return false;
    return std::all_of(s.begin(), s.end(), [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; });
}

} // namespace

// One PLC: its program, its own variables, statics and process-data cells; the Host it was
// compiled against.
struct PlcRuntime::Plc : Host {
    PlcRuntime& rt;
    PlcSource src;
    // plc<n>.* (ax<n>.plc.*): the runtime's block for this id, which code of any PLC added
    // before may already have bound (ECMC: data items shared by name)
    using Vars = PlcRuntime::PlcVars;
    Vars& vars;
    std::deque<double> cells; // statics and check-mode stand-ins (stable addresses)
    std::map<std::string, double*> statics, stand_ins;
    struct EcCell {
        registry::BoundSignal signal;
        EcEntry::Kind kind = EcEntry::Kind::Integer;
        bool writable = false;
        double value = 0, read = 0;
    };
    std::deque<EcCell> ec;
    std::map<std::string, EcCell*> ec_names;
    // ec<m>.s<k>.valid of every slave whose entries the code uses: the PLC is scanned only while
    // all are 1 (a slave missing, lost or out of OP holds it, with error kEcEntryNotValid).
    std::vector<registry::BoundSignal> slave_valid;
    std::set<std::pair<int, int>> slaves_used;
    bool held = false; // RT: not scanned in the last cycle for that reason
    // ds<n>.<item>: read from the storage before each scan, applied after it when changed
    enum class DsItem : uint8_t { Append, Data, Index, Size, Full, Clear, Error };
    struct DsCell {
        daq::DataStorage* ds = nullptr; // null when only checking
        DsItem item = DsItem::Append;
        double value = 0, read = 0;
    };
    std::deque<DsCell> ds;
    std::map<std::string, DsCell*> ds_names;
    // ax<n>.<item> whose write is an action the axis does not take from its variables (ECMC's
    // ecmcPLCDataIF::writeAxis): enc.homed marks the primary encoder homed or not. The value is
    // noted before each scan and the action taken after it when the scan changed it (as a
    // boolean, ECMC's isBool_), unless the axis refuses PLC commands (allowplccmd 0).
    struct AxisWrite {
        motion::Axis* axis = nullptr;
        double* cell = nullptr;
        double read = 0;
    };
    std::vector<AxisWrite> axis_writes;
    std::set<std::string> written; // ec entries the code assigns (bit suffix removed)
    void assigned(std::string_view name) override {
        if (name.rfind("ec", 0) != 0 || !ec_names.count(std::string(name))) return;
        std::string n(name);
        // "ec0.s3.out.2": a bit of the entry "ec0.s3.out"
        std::size_t last = n.rfind('.');
        if (last != std::string::npos && last + 1 < n.size() &&
            std::all_of(n.begin() + std::ptrdiff_t(last) + 1, n.end(), [](char c) { return c >= '0' && c <= '9'; }) &&
            std::count(n.begin(), n.end(), '.') == 3)
            n.resize(last);
        written.insert(n);
    }
    std::optional<Program> program;
    int divider = 1, counter = 0;
    bool first_done = false;
    std::atomic<int> enable_request{-1};
    std::atomic<bool> st_enabled{false}, st_firstscan{true};
    std::atomic<int> st_error{0}, st_fault_index{-1};
    std::atomic<std::uint64_t> st_scans{0}, st_faults{0};

    Plc(PlcRuntime& r, PlcSource s) : rt(r), src(std::move(s)), vars(r.plc_vars(src.id, src.axis_plc)) {}

    std::string prefix() const {
        return src.axis_plc ? std::string(SB() << "ax" << src.id << ".plc") : std::string(SB() << "plc" << src.id);
    }

    double* cell(std::map<std::string, double*>& m, const std::string& name) {
        auto it = m.find(name);
        if (it != m.end()) return it->second;
        cells.push_back(0);
        return m[name] = &cells.back();
    }

    static double* var(Vars& v, std::string_view item) {
        std::string i = lower(item);
        if (i == "enable") return &v.enable;
        if (i == "error") return &v.error;
        if (i == "scantime") return &v.scantime;
        if (i == "firstscan") return &v.firstscan;
        if (i == "dbg") return &v.dbg;
        return nullptr;
    }

    // plc<n>.* or ax<n>.plc.* of this or another PLC, added before or after this one: ECMC makes
    // them data items shared by name (ecmcPLCMain::parsePLC, addPLCDefaultVariable), so any PLC
    // may name any plc<n>; ax<n>.plc.* needs axis n.
    std::optional<Binding> plc_variable(int id, bool axis_plc, std::string_view item) {
        if (!var(vars, item)) return std::nullopt;
        if (axis_plc && !(id == src.id && src.axis_plc)) {
            bool axis = std::any_of(rt.opt_.axes.begin(), rt.opt_.axes.end(), [&](motion::Axis* a) { return a->params().id == id; });
            const auto& known = rt.opt_.known_axis_ids;
            if (rt.opt_.check_only) axis = axis || !known || std::count(known->begin(), known->end(), id);
            if (!axis) return std::nullopt;
        }
        double* a = var(id == src.id && axis_plc == src.axis_plc ? vars : rt.plc_vars(id, axis_plc), item);
        // scantime and firstscan are the runtime's; enable, error and dbg may be written
        std::string i = lower(item);
        return Binding{a, i == "enable" || i == "error" || i == "dbg", 1};
    }

    std::optional<Binding> resolve(std::string_view name) override {
        std::string n(name);
        if (n.rfind("static.", 0) == 0 && is_identifier(n.substr(7))) return Binding{cell(statics, n.substr(7)), true, 1};
        if (n.rfind("global.", 0) == 0 && is_identifier(n.substr(7))) {
            auto it = rt.globals_.find(n.substr(7));
            if (it != rt.globals_.end()) return Binding{it->second, true, 1};
            rt.globals_cells_.push_back(0);
            return Binding{rt.globals_[n.substr(7)] = &rt.globals_cells_.back(), true, 1};
        }
        int id = 0;
        std::string_view rest;
        if (split_indexed(n, "plc", id, rest)) return plc_variable(id, false, rest);
        if (split_indexed(n, "ax", id, rest)) {
            if (lower(rest).rfind("plc.", 0) == 0) return plc_variable(id, true, rest.substr(4));
            const motion::AxisVariableInfo* info = motion::find_axis_variable(lower(rest));
            if (!info) return std::nullopt;
            for (motion::Axis* a : rt.opt_.axes)
                if (a->params().id == id) {
                    double* cell = motion::axis_variable(a->variables(), *info);
                    if (std::string_view(info->name) == "enc.homed" &&
                        std::none_of(axis_writes.begin(), axis_writes.end(), [&](const AxisWrite& w) { return w.cell == cell; }))
                        axis_writes.push_back(AxisWrite{a, cell, 0});
                    return Binding{cell, info->writable, 1};
                }
            if (rt.opt_.check_only && (!rt.opt_.known_axis_ids || std::count(rt.opt_.known_axis_ids->begin(), rt.opt_.known_axis_ids->end(), id)))
                return Binding{cell(stand_ins, n), info->writable, 1};
            return std::nullopt;
        }
        if (split_indexed(n, "ec", id, rest)) return ec_entry(n);
        if (split_indexed(n, "ds", id, rest)) return ds_variable(n, id, rest);
        if (rt.opt_.cells)
            if (auto b = rt.opt_.cells(n)) return b;
        for (Plugin* p : rt.opt_.plugins)
            if (auto v = p->constant(n)) {
                cells.push_back(*v);
                return Binding{&cells.back(), false, 1};
            }
        return std::nullopt;
    }

    static std::optional<DsItem> ds_item(std::string_view item) {
        static const std::pair<const char*, DsItem> items[] = {
            {"append", DsItem::Append}, {"data", DsItem::Data},   {"index", DsItem::Index}, {"size", DsItem::Size},
            {"full", DsItem::Full},     {"clear", DsItem::Clear}, {"error", DsItem::Error}};
        std::string i = lower(item);
        for (const auto& [name, it] : items)
            if (i == name) return it;
        return std::nullopt;
    }

    // "ds0.append": a cell of data storage 0 (ECMC's ecmcPLCDataIF for storages).
    std::optional<Binding> ds_variable(const std::string& n, int id, std::string_view rest) {
        auto writable = [](DsItem i) { return i != DsItem::Full && i != DsItem::Error; };
        if (auto it = ds_names.find(n); it != ds_names.end()) return Binding{&it->second->value, writable(it->second->item), 1};
        std::optional<DsItem> item = ds_item(rest);
        if (!item || id < 0 || id >= daq::kMaxStorages) return std::nullopt;
        daq::DataStorage* storage = rt.storage_by_id_[id];
        if (!storage) {
            const auto& known = rt.opt_.known_storage_ids;
            if (!rt.opt_.check_only || (known && !std::count(known->begin(), known->end(), id))) return std::nullopt;
        }
        ds.push_back(DsCell{storage, *item});
        ds_names[n] = &ds.back();
        return Binding{&ds.back().value, writable(*item), 1};
    }

    // "ec0.s3.binaryInput01[.bit]", "ec0.masterstatus": a cell copied from/to the image.
    std::optional<Binding> ec_entry(const std::string& n) {
        if (auto it = ec_names.find(n); it != ec_names.end())
            return Binding{&it->second->value, it->second->writable, 1};
        std::string entry = n;
        int bit = -1;
        std::size_t dot = n.rfind('.');
        std::string last = n.substr(dot + 1);
        int slave = 0, m = 0;
        std::string_view after;
        if (!split_indexed(n, "ec", m, after)) return std::nullopt;
        std::string_view slave_rest;
        bool is_slave = split_indexed(after, "s", slave, slave_rest);
        if (is_slave && std::count(n.begin(), n.end(), '.') == 3 && !last.empty() &&
            std::all_of(last.begin(), last.end(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); })) {
            bit = std::stoi(last);
            entry = n.substr(0, dot);
            if (bit > 63) return std::nullopt;
        }
        std::optional<EcEntry> e;
        if (rt.opt_.ec) {
            std::string why;
            e = rt.opt_.ec(entry, why);
        }
        if (!e) {
            bool well_formed = after == "masterstatus" || (is_slave && is_identifier(std::string(slave_rest.substr(0, slave_rest.find('.')))) &&
                                                           std::count(n.begin(), n.end(), '.') == (bit >= 0 ? 3 : 2));
            if (!rt.opt_.check_only || !well_formed || rt.opt_.ec) return std::nullopt;
            e = EcEntry{{}, EcEntry::Kind::Integer, after != "masterstatus"};
        }
        std::string_view entry_name = slave_rest.substr(0, slave_rest.find('.'));
        if (is_slave && entry_name != "ONE" && entry_name != "ZERO" && entry_name != "valid" && rt.opt_.ec &&
            slaves_used.insert({m, slave}).second) {
            std::string why;
            if (auto v = rt.opt_.ec(SB() << "ec" << m << ".s" << slave << ".valid", why); v && v->signal.bound())
                slave_valid.push_back(v->signal);
        }
        ec.push_back(EcCell{e->signal, e->kind, e->writable});
        ec.back().signal.bit = bit;
        if (bit >= 0) ec.back().kind = EcEntry::Kind::Integer;
        ec_names[n] = &ec.back();
        return Binding{&ec.back().value, e->writable, 1};
    }

    std::string why_unknown(std::string_view name) override {
        std::string n(name);
        int id = 0;
        std::string_view rest;
        if (split_indexed(n, "ax", id, rest)) {
            if (lower(rest).rfind("plc.", 0) == 0) {
                if (!var(vars, rest.substr(4)))
                    return SB() << "'" << rest.substr(4) << "' is not one of enable, error, scantime, firstscan, dbg";
                return SB() << "no axis " << id << " for its axis PLC";
            }
            if (!motion::find_axis_variable(lower(rest))) return SB() << "'" << rest << "' is not an axis variable (specs: ax<n>.enc.actpos, ax<n>.traj.extsetpos, ...)";
            std::string ids;
            for (motion::Axis* a : rt.opt_.axes) ids += (ids.empty() ? "" : ", ") + std::to_string(a->params().id);
            if (rt.opt_.known_axis_ids)
                for (int k : *rt.opt_.known_axis_ids) ids += (ids.empty() ? "" : ", ") + std::to_string(k);
            return SB() << "no axis " << id << (ids.empty() ? std::string(" (the IOC has no axes)") : " (axes: " + ids + ")");
        }
        if (split_indexed(n, "plc", id, rest))
            return SB() << "'" << rest << "' is not one of enable, error, scantime, firstscan, dbg";
        if (split_indexed(n, "ec", id, rest)) {
            if (rest.find(".mm.") != std::string_view::npos) return "memory maps (mm) are not supported yet";
            if (!rt.opt_.ec) return "no such process-data entry (expected ec<m>.s<k>.<entry>[.<bit>] or ec<m>.masterstatus)";
            std::string entry = n, why;
            std::size_t dot = n.rfind('.');
            std::string last = n.substr(dot + 1);
            if (!last.empty() && std::all_of(last.begin(), last.end(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); }))
                entry = n.substr(0, dot);
            if (rt.opt_.ec(entry, why)) return "bit number out of range (0..63)";
            return why;
        }
        if (split_indexed(n, "ds", id, rest)) {
            if (!ds_item(rest)) return SB() << "'" << rest << "' is not one of append, data, index, size, full, clear, error";
            if (id >= daq::kMaxStorages) return SB() << "data storage " << id << " is out of range (ds0..ds31)";
            std::string ids;
            for (daq::DataStorage* d : rt.opt_.storages) ids += (ids.empty() ? "" : ", ") + std::to_string(d->id());
            if (rt.opt_.known_storage_ids)
                for (int k : *rt.opt_.known_storage_ids) ids += (ids.empty() ? "" : ", ") + std::to_string(k);
            return SB() << "no data storage " << id
                        << (ids.empty() ? std::string(" (the IOC has none: `storages:` in the IOC file)") : " (storages: " + ids + ")");
        }
        if (n.rfind("static.", 0) == 0 || n.rfind("global.", 0) == 0) return "not a valid variable name";
        return {};
    }

    std::optional<FunctionInfo> function(std::string_view name) override;

    void print(std::string_view text) noexcept override {
        Output o;
        o.plc = 0;
        std::string_view p = src.axis_plc ? "ax" : "plc";
        int k = std::snprintf(o.text, sizeof o.text, "%.*s%d: ", int(p.size()), p.data(), src.id);
        std::size_t room = sizeof o.text - std::size_t(k);
        std::size_t n = std::min(room, text.size());
        std::memcpy(o.text + k, text.data(), n);
        o.len = std::uint16_t(std::size_t(k) + n);
        if (!rt.output_.push(o)) rt.dropped_.fetch_add(1, std::memory_order_relaxed);
    }

    // RT: the process image into the cells.
    void copy_in() noexcept {
        for (EcCell& c : ec) {
            if (!c.signal.bound()) continue;
            double v = 0;
            if (c.kind == EcEntry::Kind::Integer || c.signal.bit >= 0) {
                v = double(c.signal.get());
            } else if (c.kind == EcEntry::Kind::Float32) {
                uint32_t raw = uint32_t(c.signal.get_raw());
                float f;
                std::memcpy(&f, &raw, 4);
                v = f;
            } else {
                uint64_t raw = c.signal.get_raw();
                std::memcpy(&v, &raw, 8);
            }
            c.value = c.read = v;
        }
    }
    // RT: the data storages' values into their cells (append and clear read NaN, as ECMC: every
    // scan that assigns them acts; data reads the element at the index, keeping the last value
    // when the index is at the end).
    void ds_in() noexcept {
        for (DsCell& c : ds) {
            if (!c.ds) continue;
            switch (c.item) {
            case DsItem::Append:
            case DsItem::Clear: c.value = std::numeric_limits<double>::quiet_NaN(); break;
            case DsItem::Data: (void)c.ds->get(double(c.ds->index()), c.value); break;
            case DsItem::Index: c.value = double(c.ds->index()); break;
            case DsItem::Size: c.value = double(c.ds->size()); break;
            case DsItem::Full: c.value = c.ds->full() ? 1 : 0; break;
            case DsItem::Error: c.value = c.ds->error(); break;
            }
            c.read = c.value;
        }
    }
    // RT: what the scan assigned, applied to the storages (only when changed).
    void ds_out() noexcept {
        for (DsCell& c : ds) {
            if (!c.ds || std::memcmp(&c.value, &c.read, sizeof(double)) == 0) continue;
            switch (c.item) {
            case DsItem::Append:
                if (!std::isnan(c.value)) (void)c.ds->append(c.value);
                break;
            case DsItem::Clear:
                if (c.value > 0) c.ds->clear();
                break;
            case DsItem::Data: (void)c.ds->set(double(c.ds->index()), c.value); break;
            case DsItem::Index: (void)c.ds->set_index(c.value); break;
            case DsItem::Size: (void)c.ds->resize(c.value); break;
            case DsItem::Full:
            case DsItem::Error: break;
            }
        }
    }

    // RT: the axis values whose writes are actions, as the scan starts; after it, the actions.
    void axis_in() noexcept {
        for (AxisWrite& w : axis_writes) w.read = *w.cell;
    }
    void axis_out() noexcept {
        for (AxisWrite& w : axis_writes) {
            if ((*w.cell != 0) == (w.read != 0) || w.axis->variables().allowplccmd == 0) continue;
            (void)w.axis->set_encoder_homed(w.axis->params().primary_encoder, *w.cell != 0);
        }
    }

    // RT: cells the scan changed back into the image (as ECMC: only when changed).
    void copy_out() noexcept {
        for (EcCell& c : ec) {
            if (!c.writable || !c.signal.bound()) continue;
            if (std::memcmp(&c.value, &c.read, sizeof(double)) == 0) continue;
            if (c.signal.bit >= 0) {
                if ((c.value != 0) == (c.read != 0)) continue;
                c.signal.set(c.value != 0 ? 1 : 0);
            } else if (c.kind == EcEntry::Kind::Float32) {
                float f = float(c.value);
                uint32_t raw;
                std::memcpy(&raw, &f, 4);
                c.signal.set(int64_t(raw));
            } else if (c.kind == EcEntry::Kind::Float64) {
                int64_t raw;
                std::memcpy(&raw, &c.value, 8);
                c.signal.set(raw);
            } else {
                if (!std::isfinite(c.value)) continue; // nothing sensible to write
                double v = std::trunc(c.value);
                v = std::clamp(v, -9.2233720368547748e18, 1.8446744073709552e19);
                c.signal.set(v >= 9.2233720368547748e18 ? int64_t(uint64_t(v)) : int64_t(v));
            }
        }
    }
};

// ---- built-in functions ----------------------------------------------------------------------

struct Builtins {
    using Plc = PlcRuntime::Plc;

    // The axis with ECMC index `id` (the axis id), as its AxisGroup index; -1 if none.
    static int axis_index(PlcRuntime& rt, double id) noexcept {
        if (!(id >= 0 && id < double(rt.axis_by_id_.size()))) return -1;
        return rt.axis_by_id_[std::size_t(id)];
    }
    static double result(PlcRuntime& rt, uint32_t code) noexcept {
        rt.mc_error_ = code;
        return code;
    }
    static double fb(PlcRuntime& rt, const double* a, int which) noexcept {
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        motion::Axis& axis = *rt.opt_.axes[std::size_t(i)];
        PlcRuntime::McMemory& m = rt.mc_[std::size_t(i)];
        bool exe = a[1] != 0;
        // ECMC: mc_move_ext_pos shares mc_move_abs's edge memory, mc_home_pos mc_home's
        bool* last = which == 0 || which == 6 ? &m.abs : which == 1 ? &m.rel : which == 2 ? &m.vel
                   : which == 3 || which == 5 ? &m.home : &m.halt;
        if (which != 4 && axis.variables().allowplccmd == 0) return result(rt, motion::error_id::kCommandsBlocked);
        if (axis.variables().traj.source != 0) return result(rt, motion::error_id::kTrajSourceNotInternal);
        bool rising = exe && !*last, falling = !exe && *last;
        *last = exe;
        if (falling && which != 4) { // a block whose execute drops halts its move (ECMC setExecute(0))
            motion::AxisCommand h{motion::CommandType::Halt};
            return result(rt, axis.command(h));
        }
        if (!rising) return 0;
        motion::AxisCommand c;
        switch (which) {
        case 0:
        case 1:
            c.type = which == 0 ? motion::CommandType::MoveAbsolute : motion::CommandType::MoveRelative;
            c.position = a[2];
            c.velocity = a[3];
            c.acceleration = a[4];
            c.deceleration = a[5];
            break;
        case 2:
            c.type = motion::CommandType::MoveVelocity;
            c.velocity = a[2];
            c.acceleration = a[3];
            c.deceleration = a[4];
            break;
        case 3:
        case 5: // mc_home_pos(ax, exe, seq, velTowardsCam, velOffCam, homePos)
            c.type = motion::CommandType::Home;
            c.homing_sequence = int(a[2]);
            if (which == 5) {
                c.position = a[5];
                c.set_home_position = true;
            }
            break;
        case 6: // mc_move_ext_pos(ax, exe, vel, acc, dec): to the PLC's setpoint (traj.extsetpos)
            c.type = motion::CommandType::MoveAbsolute;
            c.position = axis.variables().traj.extsetpos;
            c.velocity = a[2];
            c.acceleration = a[3];
            c.deceleration = a[4];
            break;
        default:
            c.type = motion::CommandType::Halt;
            break;
        }
        return result(rt, axis.command(c));
    }

    static double move_abs(void* ctx, const double* a, int) noexcept { return fb(*static_cast<PlcRuntime*>(ctx), a, 0); }
    static double move_rel(void* ctx, const double* a, int) noexcept { return fb(*static_cast<PlcRuntime*>(ctx), a, 1); }
    static double move_vel(void* ctx, const double* a, int) noexcept { return fb(*static_cast<PlcRuntime*>(ctx), a, 2); }
    static double home(void* ctx, const double* a, int) noexcept { return fb(*static_cast<PlcRuntime*>(ctx), a, 3); }
    static double halt(void* ctx, const double* a, int) noexcept { return fb(*static_cast<PlcRuntime*>(ctx), a, 4); }
    static double home_pos(void* ctx, const double* a, int) noexcept { return fb(*static_cast<PlcRuntime*>(ctx), a, 5); }
    static double move_ext_pos(void* ctx, const double* a, int) noexcept { return fb(*static_cast<PlcRuntime*>(ctx), a, 6); }

    // mc_set_traj_vel/acc/dec/jerk(ax, value): the limits of the next moves (ECMC: no COM check)
    template <int K> static double set_traj(void* ctx, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        double v[4] = {0, 0, 0, 0};
        v[K] = a[1];
        rt.opt_.axes[std::size_t(i)]->set_trajectory_limits(v[0], v[1], v[2], v[3]);
        return 0;
    }
    static double get_prim_enc(void* ctx, const double* a, int) noexcept {
        return query(ctx, a, [](motion::Axis& x) { return double(x.params().primary_encoder + 1); });
    }
    static double get_enc_homed(void* ctx, const double* a, int) noexcept { // (ax, enc from 1)
        int enc = int(a[1]);
        return query(ctx, a, [enc](motion::Axis& x) { return x.encoder_homed(enc - 1) ? 1.0 : 0.0; });
    }
    // mc_set_enc_homed(ax, enc from 1, homed): 0, or 0x14326 for no such encoder
    static double set_enc_homed(void* ctx, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        bool ok = a[1] >= 1 && a[1] <= motion::AxisStatus::kMaxEncoders &&
                  rt.opt_.axes[std::size_t(i)]->set_encoder_homed(int(a[1]) - 1, a[2] > 0);
        return ok ? 0 : result(rt, kEncIndexOutOfRange);
    }
    // mc_set_axis_error(ax, id): the axis error (it stops and disables, as its own); returns id.
    // mc_set_slaved_axis_in_error(ax): the same with 0x1432B; returns 0.
    static double set_axis_error(void* ctx, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        uint32_t id = a[1] > 0 && a[1] < 4294967296.0 ? uint32_t(a[1]) : 0;
        motion::Axis& x = *rt.opt_.axes[std::size_t(i)];
        if (id) x.raise_error(id);
        else (void)x.command(motion::AxisCommand{motion::CommandType::Reset});
        return id;
    }
    static double set_slaved_axis_in_error(void* ctx, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        rt.opt_.axes[std::size_t(i)]->raise_error(motion::error_id::kSlavedAxisInError);
        return 0;
    }
    // mc_set_prim_enc(ax, enc from 1): the control encoder (0x14328 while busy)
    static double set_prim_enc(void* ctx, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        motion::Axis& x = *rt.opt_.axes[std::size_t(i)];
        if (x.variables().blockcom != 0) return result(rt, motion::error_id::kBlockCom);
        if (!(a[1] >= 1 && a[1] <= motion::AxisStatus::kMaxEncoders)) return result(rt, motion::error_id::kPrimaryEncoderOutOfRange);
        return result(rt, x.select_primary_encoder(int(a[1]) - 1));
    }
    static double get_hw_ready(void* ctx, const double* a, int) noexcept {
        return query(ctx, a, [](motion::Axis& x) { return x.status().position_valid && x.status().error_id == 0 ? 1.0 : 0.0; });
    }

    static double power(void* ctx, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        motion::Axis& axis = *rt.opt_.axes[std::size_t(i)];
        bool on = a[1] != 0;
        if (on && axis.variables().allowplccmd == 0) return result(rt, motion::error_id::kCommandsBlocked);
        if (axis.status().enable_cmd == on) return 0;
        motion::AxisCommand c{motion::CommandType::Power};
        c.on = on;
        return result(rt, axis.command(c));
    }
    static double reset(void* ctx, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        motion::Axis& axis = *rt.opt_.axes[std::size_t(i)];
        if (axis.variables().allowplccmd == 0) return result(rt, motion::error_id::kCommandsBlocked);
        return result(rt, axis.command(motion::AxisCommand{motion::CommandType::Reset}));
    }
    // mc_set_act_pos(ax, encIndex, pos) as ECMC (encIndex from 1; the primary encoder is the one
    // that can be set here, others give 0x14326); (ax, pos) is kept for the primary encoder.
    static double set_act_pos(void* ctx, const double* a, int n) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        motion::Axis& axis = *rt.opt_.axes[std::size_t(i)];
        double pos = n >= 3 ? a[2] : a[1];
        if (n >= 3 && int(a[1]) != axis.params().primary_encoder + 1) return result(rt, kEncIndexOutOfRange);
        return result(rt, axis.command(motion::AxisCommand{motion::CommandType::SetPosition, pos}));
    }
    template <typename F> static double query(void* ctx, const double* a, F f) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) {
            rt.mc_error_ = kAxisIdOutOfRange;
            return 0;
        }
        return f(*rt.opt_.axes[std::size_t(i)]);
    }
    static double get_busy(void* ctx, const double* a, int) noexcept {
        return query(ctx, a, [](motion::Axis& x) { return x.status().busy ? 1.0 : 0.0; });
    }
    static double get_homed(void* ctx, const double* a, int) noexcept {
        return query(ctx, a, [](motion::Axis& x) { return x.status().homed ? 1.0 : 0.0; });
    }
    static double get_axis_err(void* ctx, const double* a, int) noexcept {
        return query(ctx, a, [](motion::Axis& x) { return double(x.status().error_id); });
    }
    static double get_act_pos(void* ctx, const double* a, int n) noexcept {
        int enc = n >= 2 ? int(a[1]) : 1; // ECMC: encoder index from 1
        return query(ctx, a, [enc](motion::Axis& x) {
            const motion::AxisStatus& s = x.status();
            if (enc == 1 && (s.enc_count == 0 || x.params().virtual_axis)) return s.act_pos; // virtual axis
            if (enc < 1 || enc > s.enc_count) return 0.0;
            return s.enc_pos[std::size_t(enc - 1)];
        });
    }
    static double get_enc_ready(void* ctx, const double* a, int) noexcept {
        return query(ctx, a, [](motion::Axis&) { return 1.0; });
    }
    static double get_err(void* ctx, const double*, int) noexcept { return static_cast<PlcRuntime*>(ctx)->mc_error_; }

    // ec_* bit operations on the integer part of a value (0..63), ECMC's libEc.
    static bool bit_ok(PlcRuntime& rt, double b) noexcept {
        if (b >= 0 && b < 64) return true;
        rt.ec_error_ = kEcBitsOutOfRange;
        return false;
    }
    static uint64_t u(double v) noexcept { return v >= 0 && v < 1.8446744073709552e19 ? uint64_t(v) : 0; }
    static double set_bit(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        return bit_ok(rt, a[1]) ? double(u(a[0]) | uint64_t(1) << int(a[1])) : a[0];
    }
    static double clr_bit(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        return bit_ok(rt, a[1]) ? double(u(a[0]) & ~(uint64_t(1) << int(a[1]))) : a[0];
    }
    static double flp_bit(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        return bit_ok(rt, a[1]) ? double(u(a[0]) ^ uint64_t(1) << int(a[1])) : a[0];
    }
    static double chk_bit(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        return bit_ok(rt, a[1]) ? double(u(a[0]) >> int(a[1]) & 1) : a[0];
    }
    static double wrt_bit(void* c, const double* a, int) noexcept { // (value, wrtValue, bit)
        auto& rt = *static_cast<PlcRuntime*>(c);
        if (!bit_ok(rt, a[2])) return a[0];
        uint64_t m = uint64_t(1) << int(a[2]);
        return double(a[1] > 0 ? u(a[0]) | m : u(a[0]) & ~m);
    }
    static uint64_t mask(int start, int stop) noexcept {
        int n = stop - start + 1;
        if (n <= 0) return 0;
        return n >= 64 ? ~uint64_t(0) : (uint64_t(1) << n) - 1;
    }
    static double wrt_bits(void* c, const double* a, int) noexcept { // (value, wrtValue, start, stop)
        auto& rt = *static_cast<PlcRuntime*>(c);
        if (!bit_ok(rt, a[2]) || !bit_ok(rt, a[3])) return a[0];
        int s = int(a[2]);
        uint64_t m = mask(s, int(a[3]));
        return double((u(a[0]) & ~(m << s)) | ((u(a[1]) & m) << s));
    }
    static double chk_bits(void* c, const double* a, int) noexcept { // (value, start, stop)
        auto& rt = *static_cast<PlcRuntime*>(c);
        if (!bit_ok(rt, a[1]) || !bit_ok(rt, a[2])) return a[0];
        int s = int(a[1]);
        return double(u(a[0]) >> s & mask(s, int(a[2])));
    }
    static double get_time(void* c, const double*, int) noexcept { return double(static_cast<PlcRuntime*>(c)->cycle_ns_); }
    static double get_time_l32(void* c, const double*, int) noexcept { return double(uint32_t(static_cast<PlcRuntime*>(c)->cycle_ns_)); }
    static double get_time_u32(void* c, const double*, int) noexcept { return double(uint32_t(static_cast<PlcRuntime*>(c)->cycle_ns_ >> 32)); }
    static double ec_get_err(void* c, const double*, int) noexcept { return static_cast<PlcRuntime*>(c)->ec_error_; }
    // ec_print_hex/bin(value, start, stop): bits start..stop printed (no newline), ctx the Plc
    template <bool Hex> static double print_bits(void* c, const double* a, int) noexcept {
        auto& plc = *static_cast<Plc*>(c);
        if (!bit_ok(plc.rt, a[1]) || !bit_ok(plc.rt, a[2])) return 0;
        int s0 = int(a[1]), s1 = int(a[2]);
        uint64_t v = u(a[0]) >> s0 & mask(s0, s1);
        char text[72];
        int n = 0;
        if (Hex) {
            n = std::snprintf(text, sizeof text, "%llx", static_cast<unsigned long long>(v));
        } else {
            for (int b = s1 - s0; b >= 0 && n < 64; --b) text[n++] = char('0' + (v >> b & 1));
        }
        plc.print(std::string_view(text, std::size_t(std::max(n, 0))));
        return 0;
    }
    // ec_get_time_local_nsec/sec/min/hour(ns): fields of a time in ns since 1970 (local time)
    template <int Field> static double local_time(void*, const double* a, int) noexcept {
        if (!std::isfinite(a[0]) || a[0] < 0) return 0;
        if (Field == 0) return std::fmod(a[0], 1e9);
        std::time_t t = std::time_t(a[0] / 1e9);
        std::tm tm{};
        localtime_r(&t, &tm);
        return Field == 1 ? tm.tm_sec : Field == 2 ? tm.tm_min : tm.tm_hour;
    }
    // ec_get_time_frm_src(clockId): clock_gettime(clockId) [ns], 0 for an invalid id (vDSO: no
    // system call for the usual clocks); ec_get_time_offset_mono(): ECMC's offset added to the
    // monotonic clock, 0 here (the cycle's time is its own clock)
    static double time_from_source(void*, const double* a, int) noexcept {
        if (!(a[0] >= 0 && a[0] < 16)) return 0;
        timespec ts{};
        if (clock_gettime(clockid_t(a[0]), &ts) != 0) return 0;
        return double(ts.tv_sec) * 1e9 + double(ts.tv_nsec);
    }
    static double time_offset_mono(void*, const double*, int) noexcept { return 0; }
    // ec_get_dom_state(domain): 1 if the bus of that index is OK (a domain per bus here), else 0;
    // -0x20056 for no such domain
    static double dom_state(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        if (!(a[0] >= 0 && a[0] < double(rt.opt_.bus_ok.size()))) return -double(0x20056);
        const registry::BoundSignal& s = rt.opt_.bus_ok[std::size_t(a[0])];
        return s.bound() && s.get() != 0 ? 1 : 0;
    }
    static double ec_err_rst(void* c, const double*, int) noexcept {
        static_cast<PlcRuntime*>(c)->ec_error_ = 0;
        return 0;
    }

    // ---- ds_*: data storage (ECMC's libDs); ds_errorCode is ds_error_ ---------------------------
    // The storage `id`, or null with ds_error_ set (0x20509 outside 0..31, 0x2050A none).
    static daq::DataStorage* storage(PlcRuntime& rt, double id) noexcept {
        if (!(id >= 0 && id < daq::kMaxStorages)) {
            rt.ds_error_ = daq::ds_error::kIndexOutOfRange;
            return nullptr;
        }
        daq::DataStorage* d = rt.storage_by_id_[int(id)];
        if (!d) rt.ds_error_ = daq::ds_error::kObjectNull;
        return d;
    }
    static double ds_result(PlcRuntime& rt, uint32_t code) noexcept {
        if (code) rt.ds_error_ = code;
        return code;
    }
    // Functions returning an error code return it for a bad storage too.
    static double ds_bad(PlcRuntime& rt) noexcept { return rt.ds_error_; }
    static double ds_append_data(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* d = storage(rt, a[0]);
        return d ? ds_result(rt, d->append(a[1])) : ds_bad(rt);
    }
    static double ds_clear_data(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* d = storage(rt, a[0]);
        if (!d) return ds_bad(rt);
        d->clear();
        return 0;
    }
    static double ds_get_data(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* d = storage(rt, a[0]);
        double v = 0;
        if (d) (void)ds_result(rt, d->get(a[1], v));
        return v;
    }
    static double ds_set_data(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* d = storage(rt, a[0]);
        return d ? ds_result(rt, d->set(a[1], a[2])) : ds_bad(rt);
    }
    static double ds_get_buff_id(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* d = storage(rt, a[0]);
        return d ? double(d->index()) : -1;
    }
    static double ds_set_buff_id(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* d = storage(rt, a[0]);
        return d ? ds_result(rt, d->set_index(a[1])) : ds_bad(rt);
    }
    static double ds_is_full(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* d = storage(rt, a[0]);
        return d ? (d->full() ? 1 : 0) : -1;
    }
    static double ds_get_size(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* d = storage(rt, a[0]);
        return d ? double(d->size()) : -1;
    }
    static double ds_push_asyn(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* d = storage(rt, a[0]);
        if (!d) return -1;
        d->request_push();
        return 0;
    }
    template <int Stat> static double ds_stat(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* d = storage(rt, a[0]);
        if (!d) return 0;
        return Stat == 0 ? d->average() : Stat == 1 ? d->minimum() : d->maximum();
    }
    // ds_append_to_ds(src, srcIndex, elements, dst): src[srcIndex..] appended to dst as one block
    static double ds_append_to_ds(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        daq::DataStorage* src = storage(rt, a[0]);
        daq::DataStorage* dst = storage(rt, a[3]);
        if (!src || !dst) return 0;
        if (!(a[1] >= 0 && a[1] < double(src->size()))) return ds_result(rt, daq::ds_error::kPositionOutOfRange);
        std::size_t from = std::size_t(a[1]);
        double want = std::isfinite(a[2]) && a[2] > 0 ? a[2] : 0;
        std::size_t n = std::size_t(std::min(want, double(src->size() - from)));
        return ds_result(rt, dst->append(src->data() + from, n));
    }
    // ---- ec_*mm*: memory maps (ECMC's libEc); errors go to ec_get_err -------------------------
    // (null in the list: the map of a bus that runs in another cycle than this PLC's)
    static registry::MemMap* memmap(PlcRuntime& rt, double id) noexcept {
        if (!(id >= 0 && id < double(rt.opt_.memmaps.size())) || !rt.opt_.memmaps[std::size_t(id)]) {
            rt.ec_error_ = registry::MemMap::kNull;
            return nullptr;
        }
        return rt.opt_.memmaps[std::size_t(id)];
    }
    // ec_mm_cp(src, dst): the bytes of src into dst (as many as dst holds); 0 or the error
    static double mm_cp(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        rt.ec_error_ = 0;
        registry::MemMap *src = memmap(rt, a[0]), *dst = memmap(rt, a[1]);
        if (!src || !dst) return rt.ec_error_ = registry::MemMap::kNull;
        if (src->data() && dst->data()) std::memmove(dst->data(), src->data(), std::min(src->bytes(), dst->bytes()));
        return 0;
    }
    static double mm_type(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        rt.ec_error_ = 0;
        registry::MemMap* m = memmap(rt, a[0]);
        return m ? double(m->type) : -rt.ec_error_;
    }
    static double mm_size(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        rt.ec_error_ = 0;
        registry::MemMap* m = memmap(rt, a[0]);
        return m ? double(m->count) : 0;
    }
    static double mm_get(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        rt.ec_error_ = 0;
        registry::MemMap* m = memmap(rt, a[0]);
        double v = 0;
        if (m)
            if (uint32_t e = m->get(a[1], v)) rt.ec_error_ = e, v = 0;
        return v;
    }
    static double mm_set(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        rt.ec_error_ = 0;
        registry::MemMap* m = memmap(rt, a[0]);
        if (!m) return 0; // as ECMC: 0, the error in ec_get_err
        return rt.ec_error_ = m->set(a[1], a[2]);
    }
    // ec_mm_append_to_ds[_scale_offset](mm, ds[, scale, offset]): every element appended, in order
    template <bool Scaled> static double mm_append(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        rt.ec_error_ = 0;
        registry::MemMap* m = memmap(rt, a[0]);
        if (!m) return rt.ec_error_;
        daq::DataStorage* d = storage(rt, a[1]);
        if (!d) return rt.ec_error_ = rt.ds_error_;
        for (uint32_t i = 0; i < m->count; ++i) {
            double v = 0;
            if (uint32_t e = m->get(i, v)) return rt.ec_error_ = e;
            if (Scaled) v = v * a[2] + a[3];
            if (uint32_t e = d->append(v)) return rt.ec_error_ = e;
        }
        return 0;
    }
    static double mm_push(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        registry::MemMap* m = memmap(rt, a[0]);
        if (!m) return rt.ec_error_;
        m->pushes.fetch_add(1, std::memory_order_release);
        return 0;
    }
    static double ds_get_err(void* c, const double*, int) noexcept { return static_cast<PlcRuntime*>(c)->ds_error_; }
    static double ds_err_rst(void* c, const double*, int) noexcept {
        static_cast<PlcRuntime*>(c)->ds_error_ = 0;
        return 0;
    }

    // epics_get_state(): EPICS's initHookState the IOC reached; epics_get_started(): 1 once running
    static constexpr int kAfterIocRunning = 16; // initHookAfterIocRunning
    static double epics_state(void* c, const double*, int) noexcept {
        return static_cast<PlcRuntime*>(c)->epics_state_.load(std::memory_order_relaxed);
    }
    static double epics_started(void* c, const double*, int) noexcept {
        return static_cast<PlcRuntime*>(c)->epics_state_.load(std::memory_order_relaxed) >= kAfterIocRunning ? 1 : 0;
    }

    // ---- mc_grp_*: ECMC axis groups (ecmcAxisGroup); a bad group id sets mc_errorCode --------
    static constexpr int kMaxGroups = 128;
    static const std::vector<motion::Axis*>* group(PlcRuntime& rt, double g) noexcept {
        if (!(g >= 0 && g < kMaxGroups)) {
            rt.mc_error_ = kAxisIdOutOfRange; // ECMC checks groups as axes: 0x20502
            return nullptr;
        }
        if (g >= double(rt.groups_.size())) {
            rt.mc_error_ = kAxisObjectNull; // 0x20508: no such group
            return nullptr;
        }
        return &rt.groups_[std::size_t(g)];
    }
    // "all" (an empty group: false, as ECMC) / "any" of a member predicate; 0 for a bad group
    template <bool All, typename F> static double grp_test(void* c, const double* a, F f) noexcept {
        const auto* g = group(*static_cast<PlcRuntime*>(c), a[0]);
        if (!g || g->empty()) return 0;
        for (motion::Axis* x : *g)
            if (f(*x) != All) return All ? 0 : 1;
        return All ? 1 : 0;
    }
    static double grp_get_enable(void* c, const double* a, int) noexcept {
        return grp_test<true>(c, a, [](motion::Axis& x) { return x.status().enable_cmd; });
    }
    static double grp_get_any_enable(void* c, const double* a, int) noexcept {
        return grp_test<false>(c, a, [](motion::Axis& x) { return x.status().enable_cmd; });
    }
    static double grp_get_enabled(void* c, const double* a, int) noexcept {
        return grp_test<true>(c, a, [](motion::Axis& x) { return x.status().enabled && x.status().enable_cmd; });
    }
    static double grp_get_any_enabled(void* c, const double* a, int) noexcept {
        return grp_test<false>(c, a, [](motion::Axis& x) { return x.status().enabled; });
    }
    static double grp_get_busy(void* c, const double* a, int) noexcept {
        return grp_test<true>(c, a, [](motion::Axis& x) { return x.status().busy; });
    }
    static double grp_get_any_busy(void* c, const double* a, int) noexcept {
        return grp_test<false>(c, a, [](motion::Axis& x) { return x.status().busy; });
    }
    static double grp_get_traj_src_ext(void* c, const double* a, int) noexcept {
        return grp_test<true>(c, a, [](motion::Axis& x) { return x.variables().traj.source != 0; });
    }
    static double grp_get_any_traj_src_ext(void* c, const double* a, int) noexcept {
        return grp_test<false>(c, a, [](motion::Axis& x) { return x.variables().traj.source != 0; });
    }
    static double grp_get_any_at_fwd_limit(void* c, const double* a, int) noexcept {
        return grp_test<false>(c, a, [](motion::Axis& x) { return x.status().limit_fwd; });
    }
    static double grp_get_any_at_bwd_limit(void* c, const double* a, int) noexcept {
        return grp_test<false>(c, a, [](motion::Axis& x) { return x.status().limit_bwd; });
    }
    static double grp_get_any_at_limit(void* c, const double* a, int) noexcept {
        return grp_test<false>(c, a, [](motion::Axis& x) { return x.status().limit_fwd || x.status().limit_bwd; });
    }
    static double grp_get_any_ilocked(void* c, const double* a, int) noexcept {
        return grp_test<false>(c, a, [](motion::Axis& x) { return x.status().ilock_fwd || x.status().ilock_bwd; });
    }
    static double grp_get_ctrl_within_db(void* c, const double* a, int) noexcept {
        return grp_test<true>(c, a, [](motion::Axis& x) { return x.within_controller_deadband(); });
    }
    static double grp_get_any_error_id(void* c, const double* a, int) noexcept {
        const auto* g = group(*static_cast<PlcRuntime*>(c), a[0]);
        if (g)
            for (motion::Axis* x : *g)
                if (x->status().error_id) return x->status().error_id;
        return 0;
    }
    static double grp_axis_in_grp(void* c, const double* a, int) noexcept {
        return grp_test<false>(c, a, [id = a[1]](motion::Axis& x) { return double(x.params().id) == id; });
    }
    static double grp_size(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        const auto* g = group(rt, a[0]);
        return g ? double(g->size()) : rt.mc_error_;
    }
    // Each member in turn; the first error stops it and is returned ("Rerr" functions; a bad
    // group returns its error code). R0: the same, returning 0 whatever happened.
    template <bool ReturnsError, typename F> static double grp_each(void* c, const double* a, F f) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        const auto* g = group(rt, a[0]);
        if (!g) return ReturnsError ? rt.mc_error_ : 0;
        for (motion::Axis* x : *g)
            if (uint32_t e = f(*x)) return ReturnsError ? result(rt, e) : 0;
        return 0;
    }
    static uint32_t power(motion::Axis& x, bool on) noexcept {
        if (x.status().enable_cmd == on) return 0;
        motion::AxisCommand p{motion::CommandType::Power};
        p.on = on;
        return x.command(p);
    }
    static double grp_set_enable(void* c, const double* a, int) noexcept {
        bool on = a[1] != 0;
        return grp_each<true>(c, a, [on](motion::Axis& x) { return power(x, on); });
    }
    static double grp_set_traj_src(void* c, const double* a, int) noexcept {
        int src = int(a[1]);
        return grp_each<true>(c, a, [src](motion::Axis& x) { return x.set_traj_source(src); });
    }
    static double grp_set_enc_src(void* c, const double* a, int) noexcept {
        int src = int(a[1]);
        return grp_each<true>(c, a, [src](motion::Axis& x) { return x.set_enc_source(src); });
    }
    static double grp_reset_error(void* c, const double* a, int) noexcept {
        grp_each<true>(c, a, [](motion::Axis& x) {
            (void)x.command(motion::AxisCommand{motion::CommandType::Reset});
            return 0u;
        });
        return 0;
    }
    static double grp_set_error(void* c, const double* a, int) noexcept {
        uint32_t id = a[1] > 0 && a[1] < 4294967296.0 ? uint32_t(a[1]) : 0;
        return grp_each<true>(c, a, [id](motion::Axis& x) {
            if (id) x.raise_error(id);
            else (void)x.command(motion::AxisCommand{motion::CommandType::Reset});
            return 0u;
        });
    }
    template <uint32_t Id, bool ReturnsError> static double grp_raise(void* c, const double* a, int) noexcept {
        return grp_each<ReturnsError>(c, a, [](motion::Axis& x) {
            x.raise_error(Id);
            return 0u;
        });
    }
    static double grp_halt(void* c, const double* a, int) noexcept {
        return grp_each<true>(c, a, [](motion::Axis& x) {
            (void)x.command(motion::AxisCommand{motion::CommandType::Halt});
            return 0u;
        });
    }
    template <typename F> static double grp_set(void* c, const double* a, F f) noexcept {
        return grp_each<false>(c, a, [&](motion::Axis& x) {
            f(x, a[1] != 0);
            return 0u;
        });
    }
    static double grp_set_allow_src_change(void* c, const double* a, int) noexcept {
        return grp_set(c, a, [](motion::Axis& x, bool on) { x.set_allow_source_change(on); });
    }
    static double grp_set_autoenable_enable(void* c, const double* a, int) noexcept {
        return grp_set(c, a, [](motion::Axis& x, bool on) { x.set_auto_enable(on); });
    }
    static double grp_set_autodisable_enable(void* c, const double* a, int) noexcept {
        return grp_set(c, a, [](motion::Axis& x, bool on) { x.set_auto_disable(on); });
    }
    static double grp_set_ctrl_within_db(void* c, const double* a, int) noexcept {
        return grp_set(c, a, [](motion::Axis& x, bool on) { x.set_within_deadband_external(on); });
    }
    // motor-record requests (ECMC: the record's SYNC, STOP, CNEN), acted on when set to 1
    static double grp_mr_set_sync(void* c, const double* a, int) noexcept {
        return grp_set(c, a, [](motion::Axis& x, bool on) { if (on) x.request_mr_sync(); });
    }
    static double grp_mr_set_stop(void* c, const double* a, int) noexcept {
        return grp_set(c, a, [](motion::Axis& x, bool on) { if (on) x.request_mr_stop(); });
    }
    static double grp_mr_set_cnen(void* c, const double* a, int) noexcept {
        return grp_set(c, a, [](motion::Axis& x, bool on) { (void)power(x, on); });
    }
    static double grp_ignore(void* c, const double* a, int) noexcept { // no status check at disable here
        return grp_set(c, a, [](motion::Axis&, bool) {});
    }
    // mc_mr_set_sync/stop/cnen(ax, value): one axis's motor record (refused while blockcom)
    template <int Which> static double mr_set(void* ctx, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        motion::Axis& x = *rt.opt_.axes[std::size_t(i)];
        if (x.variables().blockcom != 0) return result(rt, motion::error_id::kBlockCom);
        if (x.variables().allowplccmd == 0) return result(rt, motion::error_id::kCommandsBlocked);
        bool on = a[1] != 0;
        if (Which == 0 && on) x.request_mr_sync();
        if (Which == 1 && on) x.request_mr_stop();
        if (Which == 2) return result(rt, power(x, on));
        return 0;
    }
    // mc_set_enable_motion_funcs(ax, positioning, constantVelocity, homing): allowedFunctions
    static double set_motion_funcs(void* ctx, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(ctx);
        int i = axis_index(rt, a[0]);
        if (i < 0) return result(rt, uint32_t(kAxisIdOutOfRange));
        motion::Axis& x = *rt.opt_.axes[std::size_t(i)];
        if (x.variables().blockcom != 0) return result(rt, motion::error_id::kBlockCom);
        x.set_allowed_functions(a[1] != 0, a[2] != 0, a[3] != 0);
        return 0;
    }
    static double set_autoenable(void* ctx, const double* a, int) noexcept {
        return query(ctx, a, [on = a[1] != 0](motion::Axis& x) { x.set_auto_enable(on); return 0.0; });
    }
    static double set_autodisable(void* ctx, const double* a, int) noexcept {
        return query(ctx, a, [on = a[1] != 0](motion::Axis& x) { x.set_auto_disable(on); return 0.0; });
    }

    // lut_get_value(lut, x): the table's linear interpolation at x; 0 for a missing table
    static double lut_get_value(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        if (!(a[0] >= 0 && a[0] < PlcRuntime::kMaxLuts)) return 0;
        const LookupTable* t = rt.lut_by_id_[int(a[0])];
        return t ? t->value(a[1]) : 0;
    }

    // ---- m2m_*: values shared with the PLCs of other IOCs (plc/m2m.hpp) -----------------------
    static double m2m_fail(PlcRuntime& rt, uint32_t code) noexcept {
        rt.m2m_error_ = code;
        return code;
    }
    static double m2m_write(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        if (!rt.opt_.m2m) return m2m_fail(rt, M2m::kNotValid);
        uint32_t e = rt.opt_.m2m->write(a[0], a[1]);
        return e ? m2m_fail(rt, e) : 0;
    }
    static double m2m_read(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        if (!rt.opt_.m2m) {
            m2m_fail(rt, M2m::kNotValid);
            return 0;
        }
        uint32_t e = 0;
        double v = rt.opt_.m2m->read(a[0], e);
        if (e) m2m_fail(rt, e);
        return v;
    }
    static double m2m_stat(void* c, const double*, int) noexcept {
        return static_cast<PlcRuntime*>(c)->opt_.m2m ? 1 : -double(M2m::kNotValid);
    }
    static double m2m_get_err(void* c, const double*, int) noexcept { return static_cast<PlcRuntime*>(c)->m2m_error_; }
    static double m2m_err_rst(void* c, const double*, int) noexcept {
        static_cast<PlcRuntime*>(c)->m2m_error_ = 0;
        return 0;
    }
    static double m2m_ioc_run(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        return rt.opt_.m2m ? rt.opt_.m2m->ioc_running(a[0]) : -1;
    }
    static double m2m_ioc_ec_ok(void* c, const double* a, int) noexcept {
        auto& rt = *static_cast<PlcRuntime*>(c);
        return rt.opt_.m2m ? rt.opt_.m2m->ioc_ec_ok(a[0]) : -1;
    }

    // A plugin function: ctx is the Plugin::Function.
    static double plugin(void* ctx, const double* a, int) noexcept {
        return static_cast<const Plugin::Function*>(ctx)->fn(a);
    }
};

std::optional<Host::FunctionInfo> PlcRuntime::Plc::function(std::string_view name) {
    struct Entry {
        const char* name;
        Host::Function fn;
        int min, max;
        bool motion; // needs axes (any name is fine when only checking)
    };
    static const Entry table[] = {
        {"mc_move_abs", Builtins::move_abs, 6, 6, true},   {"mc_move_rel", Builtins::move_rel, 6, 6, true},
        {"mc_move_vel", Builtins::move_vel, 5, 5, true},   {"mc_home", Builtins::home, 5, 5, true},
        {"mc_halt", Builtins::halt, 2, 2, true},           {"mc_power", Builtins::power, 2, 2, true},
        {"mc_reset", Builtins::reset, 1, 1, true},         {"mc_get_busy", Builtins::get_busy, 1, 1, true},
        {"mc_get_homed", Builtins::get_homed, 1, 1, true}, {"mc_get_axis_err", Builtins::get_axis_err, 1, 1, true},
        {"mc_get_act_pos", Builtins::get_act_pos, 1, 2, true}, {"mc_set_act_pos", Builtins::set_act_pos, 2, 3, true},
        {"mc_get_enc_ready", Builtins::get_enc_ready, 1, 2, true}, {"mc_get_err", Builtins::get_err, 0, 0, false},
        {"ec_set_bit", Builtins::set_bit, 2, 2, false},    {"ec_clr_bit", Builtins::clr_bit, 2, 2, false},
        {"ec_flp_bit", Builtins::flp_bit, 2, 2, false},    {"ec_chk_bit", Builtins::chk_bit, 2, 2, false},
        {"ec_wrt_bit", Builtins::wrt_bit, 3, 3, false},    {"ec_wrt_bits", Builtins::wrt_bits, 4, 4, false},
        {"ec_chk_bits", Builtins::chk_bits, 3, 3, false},  {"ec_get_time", Builtins::get_time, 0, 0, false},
        {"ec_get_time_l32", Builtins::get_time_l32, 0, 0, false}, {"ec_get_time_u32", Builtins::get_time_u32, 0, 0, false},
        {"ec_get_err", Builtins::ec_get_err, 0, 0, false}, {"ec_err_rst", Builtins::ec_err_rst, 0, 0, false},
        {"mc_home_pos", Builtins::home_pos, 6, 6, true},   {"mc_move_ext_pos", Builtins::move_ext_pos, 5, 5, true},
        {"mc_set_traj_vel", Builtins::set_traj<0>, 2, 2, true}, {"mc_set_traj_acc", Builtins::set_traj<1>, 2, 2, true},
        {"mc_set_traj_dec", Builtins::set_traj<2>, 2, 2, true}, {"mc_set_traj_jerk", Builtins::set_traj<3>, 2, 2, true},
        {"mc_get_prim_enc", Builtins::get_prim_enc, 1, 1, true}, {"mc_get_enc_homed", Builtins::get_enc_homed, 2, 2, true},
        {"mc_get_hw_ready", Builtins::get_hw_ready, 1, 1, true},
        {"ec_get_time_local_nsec", Builtins::local_time<0>, 1, 1, false},
        {"ec_get_time_local_sec", Builtins::local_time<1>, 1, 1, false},
        {"ec_get_time_local_min", Builtins::local_time<2>, 1, 1, false},
        {"ec_get_time_local_hour", Builtins::local_time<3>, 1, 1, false},
        {"ds_append_data", Builtins::ds_append_data, 2, 2, false}, {"ds_clear_data", Builtins::ds_clear_data, 1, 1, false},
        {"ds_get_data", Builtins::ds_get_data, 2, 2, false},   {"ds_set_data", Builtins::ds_set_data, 3, 3, false},
        {"ds_get_buff_id", Builtins::ds_get_buff_id, 1, 1, false}, {"ds_set_buff_id", Builtins::ds_set_buff_id, 2, 2, false},
        {"ds_is_full", Builtins::ds_is_full, 1, 1, false},     {"ds_get_size", Builtins::ds_get_size, 1, 1, false},
        {"ds_push_asyn", Builtins::ds_push_asyn, 1, 1, false}, {"ds_get_avg", Builtins::ds_stat<0>, 1, 1, false},
        {"ds_get_min", Builtins::ds_stat<1>, 1, 1, false},     {"ds_get_max", Builtins::ds_stat<2>, 1, 1, false},
        {"ds_append_to_ds", Builtins::ds_append_to_ds, 4, 4, false}, {"ds_get_err", Builtins::ds_get_err, 0, 0, false},
        {"ds_err_rst", Builtins::ds_err_rst, 0, 0, false},
        {"ec_mm_cp", Builtins::mm_cp, 2, 2, false},            {"ec_get_mm_type", Builtins::mm_type, 1, 1, false},
        {"ec_get_mm_data", Builtins::mm_get, 2, 2, false},     {"ec_set_mm_data", Builtins::mm_set, 3, 3, false},
        {"ec_get_mm_size", Builtins::mm_size, 1, 1, false},
        {"ec_mm_append_to_ds", Builtins::mm_append<false>, 2, 2, false},
        {"ec_mm_append_to_ds_scale_offset", Builtins::mm_append<true>, 4, 4, false},
        {"ec_mm_push_asyn", Builtins::mm_push, 1, 1, false},
        {"epics_get_state", Builtins::epics_state, 0, 0, false}, {"epics_get_started", Builtins::epics_started, 0, 0, false},
        {"mc_grp_get_enable", Builtins::grp_get_enable, 1, 1, true},
        {"mc_grp_get_any_enable", Builtins::grp_get_any_enable, 1, 1, true},
        {"mc_grp_get_enabled", Builtins::grp_get_enabled, 1, 1, true},
        {"mc_grp_get_any_enabled", Builtins::grp_get_any_enabled, 1, 1, true},
        {"mc_grp_get_busy", Builtins::grp_get_busy, 1, 1, true},
        {"mc_grp_get_any_busy", Builtins::grp_get_any_busy, 1, 1, true},
        {"mc_grp_get_any_error_id", Builtins::grp_get_any_error_id, 1, 1, true},
        {"mc_grp_set_enable", Builtins::grp_set_enable, 2, 2, true},
        {"mc_grp_set_traj_src", Builtins::grp_set_traj_src, 2, 2, true},
        {"mc_grp_set_enc_src", Builtins::grp_set_enc_src, 2, 2, true},
        {"mc_grp_reset_error", Builtins::grp_reset_error, 1, 1, true},
        {"mc_grp_set_error", Builtins::grp_set_error, 2, 2, true},
        {"mc_grp_set_slaved_axis_in_error", Builtins::grp_raise<motion::error_id::kSlavedAxisInError, true>, 1, 1, true},
        {"mc_grp_set_slaved_axis_ilocked", Builtins::grp_raise<motion::error_id::kSlavedAxisInterlock, false>, 1, 1, true},
        {"mc_grp_halt", Builtins::grp_halt, 1, 1, true},
        {"mc_grp_axis_in_grp", Builtins::grp_axis_in_grp, 2, 2, true},
        {"mc_grp_size", Builtins::grp_size, 1, 1, true},
        {"mc_grp_get_traj_src_ext", Builtins::grp_get_traj_src_ext, 1, 1, true},
        {"mc_grp_get_any_traj_src_ext", Builtins::grp_get_any_traj_src_ext, 1, 1, true},
        {"mc_grp_set_allow_src_change_when_enabled", Builtins::grp_set_allow_src_change, 2, 2, true},
        {"mc_grp_mr_set_sync", Builtins::grp_mr_set_sync, 2, 2, true},
        {"mc_grp_mr_set_stop", Builtins::grp_mr_set_stop, 2, 2, true},
        {"mc_grp_mr_set_cnen", Builtins::grp_mr_set_cnen, 2, 2, true},
        {"mc_grp_set_ignore_mr_status_check_at_disable", Builtins::grp_ignore, 2, 2, true},
        {"mc_grp_get_any_at_fwd_limit", Builtins::grp_get_any_at_fwd_limit, 1, 1, true},
        {"mc_grp_get_any_at_bwd_limit", Builtins::grp_get_any_at_bwd_limit, 1, 1, true},
        {"mc_grp_get_any_at_limit", Builtins::grp_get_any_at_limit, 1, 1, true},
        {"mc_grp_get_any_ilocked", Builtins::grp_get_any_ilocked, 1, 1, true},
        {"mc_grp_set_autoenable_enable", Builtins::grp_set_autoenable_enable, 2, 2, true},
        {"mc_grp_set_autodisable_enable", Builtins::grp_set_autodisable_enable, 2, 2, true},
        {"mc_grp_set_ctrl_within_db", Builtins::grp_set_ctrl_within_db, 2, 2, true},
        {"mc_grp_get_ctrl_within_db", Builtins::grp_get_ctrl_within_db, 1, 1, true},
        {"mc_mr_set_sync", Builtins::mr_set<0>, 2, 2, true}, {"mc_mr_set_stop", Builtins::mr_set<1>, 2, 2, true},
        {"mc_mr_set_cnen", Builtins::mr_set<2>, 2, 2, true},
        {"mc_set_autoenable_enable", Builtins::set_autoenable, 2, 2, true},
        {"mc_set_autodisable_enable", Builtins::set_autodisable, 2, 2, true},
        {"lut_get_value", Builtins::lut_get_value, 2, 2, false},
        {"mc_set_enable_motion_funcs", Builtins::set_motion_funcs, 4, 4, true},
        {"mc_set_prim_enc", Builtins::set_prim_enc, 2, 2, true},
        {"mc_set_enc_homed", Builtins::set_enc_homed, 3, 3, true},
        {"mc_set_axis_error", Builtins::set_axis_error, 2, 2, true},
        {"mc_set_slaved_axis_in_error", Builtins::set_slaved_axis_in_error, 1, 1, true},
        {"ec_get_time_frm_src", Builtins::time_from_source, 1, 1, false},
        {"ec_get_time_offset_mono", Builtins::time_offset_mono, 0, 0, false},
        {"ec_get_dom_state", Builtins::dom_state, 1, 1, false},
        {"m2m_write", Builtins::m2m_write, 2, 2, false},   {"m2m_read", Builtins::m2m_read, 1, 1, false},
        {"m2m_stat", Builtins::m2m_stat, 0, 0, false},     {"m2m_get_err", Builtins::m2m_get_err, 0, 0, false},
        {"m2m_err_rst", Builtins::m2m_err_rst, 0, 0, false}, {"m2m_ioc_run", Builtins::m2m_ioc_run, 1, 1, false},
        {"m2m_ioc_ec_ok", Builtins::m2m_ioc_ec_ok, 1, 1, false},
    };
    std::string n = lower(name);
    if (n.rfind("m2m_", 0) == 0) rt.uses_m2m_ = true;
    if (n == "ec_print_hex") return FunctionInfo{Builtins::print_bits<true>, this, 3, 3};
    if (n == "ec_print_bin") return FunctionInfo{Builtins::print_bits<false>, this, 3, 3};
    for (const Entry& e : table)
        if (n == e.name) return FunctionInfo{e.fn, &rt, e.min, e.max};
    for (Plugin* p : rt.opt_.plugins)
        if (const Plugin::Function* f = p->function(name))
            return FunctionInfo{Builtins::plugin, const_cast<Plugin::Function*>(f), f->nargs, f->nargs};
    return std::nullopt;
}

// ---- the runtime -----------------------------------------------------------------------------

PlcRuntime::PlcRuntime(Options options) : opt_(std::move(options)), output_(256) {
    for (const auto& ids : opt_.groups) {
        groups_.emplace_back();
        for (int id : ids)
            for (motion::Axis* a : opt_.axes)
                if (a->params().id == id) groups_.back().push_back(a);
    }
    for (const auto& [id, t] : opt_.luts)
        if (id >= 0 && id < kMaxLuts) lut_by_id_[id] = t;
    for (daq::DataStorage* d : opt_.storages)
        if (d && d->id() >= 0 && d->id() < daq::kMaxStorages) storage_by_id_[d->id()] = d;
    axis_plcs_.assign(opt_.axes.size(), nullptr);
    mc_.assign(opt_.axes.size(), McMemory{});
    for (std::size_t i = 0; i < opt_.axes.size(); ++i) {
        int id = opt_.axes[i]->params().id;
        if (id < 0) continue;
        if (std::size_t(id) >= axis_by_id_.size()) axis_by_id_.resize(std::size_t(id) + 1, -1);
        axis_by_id_[std::size_t(id)] = int(i);
    }
}

PlcRuntime::~PlcRuntime() = default;

PlcRuntime::PlcVars& PlcRuntime::plc_vars(int id, bool axis_plc) {
    auto& v = plc_vars_[{id, axis_plc}];
    if (!v) v = std::make_unique<PlcVars>();
    return *v;
}

void PlcRuntime::add(const PlcSource& source) {
    for (auto& p : plcs_)
        if (p->src.id == source.id && p->src.axis_plc == source.axis_plc)
            throw Error(SB() << source.file << ": " << p->prefix() << " is defined twice (first in " << p->src.file << ")");
    auto p = std::make_unique<Plc>(*this, source);
    int axis_index = -1;
    if (source.axis_plc) {
        for (std::size_t i = 0; i < opt_.axes.size(); ++i)
            if (opt_.axes[i]->params().id == source.id) axis_index = int(i);
        if (axis_index < 0 && !opt_.check_only) throw Error(SB() << source.file << ": no axis " << source.id << " for its axis PLC");
    } else {
        if (source.id < 0) throw Error(SB() << source.file << ": PLC id " << source.id << " should be >= 0");
        if (source.rate_ms == 0 || (source.rate_ms < 0 && source.rate_ms != -1) || !std::isfinite(source.rate_ms))
            throw Error(SB() << source.file << ": rate_ms " << source.rate_ms << " should be > 0 (or -1: every cycle)");
        double cycles = source.rate_ms > 0 ? source.rate_ms * 1e-3 / opt_.cycle_s : 1;
        p->divider = std::max(1, int(std::lround(cycles)));
    }
    p->vars.scantime = p->divider * opt_.cycle_s;
    p->vars.enable = source.enable ? 1 : 0;
    CompileOptions co;
    co.macros = source.macros;
    std::string self = p->prefix();
    co.macros.emplace("SELF", self);
    co.macros.emplace("SELF_ID", std::to_string(source.id));
    co.macros.emplace("M", "ec0");
    co.macros.emplace("M_ID", "0");
    co.include_path = source.include_path;
    co.libraries = source.libraries;
    co.strict = source.strict;
    co.max_loop_iterations = opt_.loop_budget;
    p->program.emplace(Program::compile(source.text, source.file, *p, co));
    p->st_enabled = source.enable;
    if (axis_index >= 0) axis_plcs_[std::size_t(axis_index)] = p.get();
    plcs_.push_back(std::move(p));
}

std::vector<std::string> PlcRuntime::written_entries(std::size_t i) const {
    const auto& w = plcs_.at(i)->written;
    return {w.begin(), w.end()};
}

bool PlcRuntime::buses_ok() noexcept {
    if (started_) return true;
    for (const registry::BoundSignal& s : opt_.bus_ok)
        if (s.bound() && s.get() == 0) return false;
    started_ = true;
    return true;
}

void PlcRuntime::scan(Plc& p, const rt::CycleInfo& c) noexcept {
    cycle_ns_ = c.t_ns;
    int req = p.enable_request.exchange(-1, std::memory_order_acq_rel);
    if (req >= 0) {
        if (req && p.vars.enable == 0) p.vars.error = 0; // enabling clears a latched fault
        p.vars.enable = req;
    }
    p.st_enabled.store(p.vars.enable != 0, std::memory_order_relaxed);
    if (p.vars.enable == 0) return;
    if (p.counter < p.divider - 1) { // ECMC: skip cycles, then run
        ++p.counter;
        return;
    }
    p.counter = 0;
    if (!buses_ok()) return; // PLCs wait for the first cycle with every bus OK
    bool data_ok = true;
    for (const registry::BoundSignal& v : p.slave_valid) data_ok = data_ok && v.get() != 0;
    if (!data_ok) { // a slave it reads or writes is missing, lost or not in OP: hold the PLC
        p.held = true;
        p.vars.error = kEcEntryNotValid;
        p.st_error.store(int(p.vars.error), std::memory_order_relaxed);
        return;
    }
    if (p.held) { // its slaves are back: it runs again, the error it was held with cleared
        p.held = false;
        if (p.vars.error == kEcEntryNotValid) p.vars.error = 0;
    }
    p.vars.firstscan = p.first_done ? 0 : 1;
    p.copy_in();
    p.ds_in();
    p.axis_in();
    int r = p.program->run();
    p.copy_out();
    p.ds_out();
    p.axis_out();
    p.first_done = true;
    p.st_firstscan.store(false, std::memory_order_relaxed);
    p.st_scans.fetch_add(1, std::memory_order_relaxed);
    if (r != 0) {
        p.vars.error = r;
        p.st_fault_index.store(p.program->fault_index(), std::memory_order_relaxed);
        p.st_faults.fetch_add(1, std::memory_order_relaxed);
    }
    p.st_error.store(int(p.vars.error), std::memory_order_relaxed);
    p.st_enabled.store(p.vars.enable != 0, std::memory_order_relaxed);
}

void PlcRuntime::run(const rt::CycleInfo& c) noexcept {
    if (opt_.m2m) { // this IOC's state for the others' m2m_ioc_run / m2m_ioc_ec_ok
        bool ok = true;
        for (const registry::BoundSignal& s : opt_.bus_ok) ok = ok && (!s.bound() || s.get() != 0);
        opt_.m2m->set_state(ok);
    }
    for (auto& p : plcs_)
        if (!p->src.axis_plc) scan(*p, c);
    for (Plugin* p : opt_.plugins) (void)p->realtime(0); // after the general PLCs (plugin.h)
}

void PlcRuntime::before_axis(std::size_t index, const rt::CycleInfo& c) noexcept {
    if (index < axis_plcs_.size() && axis_plcs_[index]) scan(*axis_plcs_[index], c);
}

const PlcSource& PlcRuntime::source(std::size_t i) const {
    return plcs_.at(i)->src;
}

std::string PlcRuntime::prefix(std::size_t i) const {
    return plcs_.at(i)->prefix();
}

void PlcRuntime::request_enable(std::size_t i, bool on) noexcept {
    if (i < plcs_.size()) plcs_[i]->enable_request.store(on ? 1 : 0, std::memory_order_release);
}

PlcRuntime::Status PlcRuntime::status(std::size_t i) const noexcept {
    Status s;
    if (i >= plcs_.size()) return s;
    const Plc& p = *plcs_[i];
    s.enabled = p.st_enabled.load(std::memory_order_relaxed);
    s.firstscan = p.st_firstscan.load(std::memory_order_relaxed);
    s.error = p.st_error.load(std::memory_order_relaxed);
    s.scantime_s = p.divider * opt_.cycle_s;
    s.scans = p.st_scans.load(std::memory_order_relaxed);
    s.faults = p.st_faults.load(std::memory_order_relaxed);
    return s;
}

std::string PlcRuntime::fault(std::size_t i) const {
    if (i >= plcs_.size()) return {};
    const Plc& p = *plcs_[i];
    int e = p.st_error.load(std::memory_order_relaxed);
    if (e == 0) return {};
    std::string where = p.program->location(p.st_fault_index.load(std::memory_order_relaxed));
    return where + (where.empty() ? "" : ": ") + to_string(RunStatus(e));
}

bool PlcRuntime::pop_output(std::string& text) {
    Output o;
    if (!output_.pop(o)) return false;
    text.assign(o.text, o.len);
    return true;
}

const double* PlcRuntime::global(const std::string& name) const {
    auto it = globals_.find(name);
    return it == globals_.end() ? nullptr : it->second;
}

const double* PlcRuntime::static_variable(std::size_t plc, const std::string& name) const {
    if (plc >= plcs_.size()) return nullptr;
    auto it = plcs_[plc]->statics.find(name);
    return it == plcs_[plc]->statics.end() ? nullptr : it->second;
}

} // namespace beamctl::plc
