#include "ioc/kinematics.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "plc/program.hpp"

#include <charconv>
#include <cmath>
#include <map>
#include <set>

namespace beamctl::ioc {
namespace {
log::Logger lg("ioc.kinematics");

// "ax12" -> 12, else -1.
int axis_number(std::string_view name) {
    if (name.size() < 3 || name.substr(0, 2) != "ax") return -1;
    int n = -1;
    auto [p, ec] = std::from_chars(name.data() + 2, name.data() + name.size(), n);
    return ec == std::errc() && p == name.data() + name.size() ? n : -1;
}

} // namespace

// The transform's storage: virtual inputs, real outputs; the program is bound to them.
class PlcInverse final : public motion::Inverse, private plc::Host {
public:
    PlcInverse(const config::KinematicsEntry& e, const std::string& ioc_file)
        : virt_ids_(e.virt), real_ids_(e.real), in_(e.virt.size()), out_(e.real.size()) {
        plc::CompileOptions o;
        o.macros = e.macros;
        o.include_path = e.include;
        o.max_loop_iterations = 100000; // a transform is straight-line code; a runaway loop faults
        if (e.file.empty()) { // inline: errors name the lines of the IOC file
            o.origin = e.code_at;
            o.origin_block = e.code_block;
            o.origin_label = SB() << "kinematics '" << e.name << "' inverse";
        }
        std::string name = e.file.empty() ? std::string(SB() << (e.where.empty() ? ioc_file : e.where) << ": kinematics '" << e.name << "' inverse") : e.file;
        program_ = std::make_unique<plc::Program>(e.file.empty() ? plc::Program::compile(e.code, name, *this, o)
                                                                 : plc::Program::compile_file(e.file, *this, o));
        // Every real axis must be assigned (at the all-zero pose, at least).
        std::fill(out_.begin(), out_.end(), NAN);
        (void)program_->run();
        for (std::size_t k = 0; k < out_.size(); ++k)
            if (std::isnan(out_[k]))
                throw Error(SB() << e.where << ": kinematics '" << e.name << "': the inverse does not assign ax" << real_ids_[k]
                                 << " (a real axis of the group)");
    }
    bool evaluate(const double* virt, double* real) noexcept override {
        for (std::size_t i = 0; i < in_.size(); ++i) in_[i] = virt[i];
        if (program_->run() != 0) return false;
        bool ok = true;
        for (std::size_t k = 0; k < out_.size(); ++k) {
            real[k] = out_[k];
            ok = ok && std::isfinite(out_[k]);
        }
        return ok;
    }

private:
    std::optional<plc::Binding> resolve(std::string_view name) override {
        int n = axis_number(name);
        for (std::size_t i = 0; i < virt_ids_.size(); ++i)
            if (virt_ids_[i] == n) return plc::Binding{&in_[i], false, 1};
        for (std::size_t k = 0; k < real_ids_.size(); ++k)
            if (real_ids_[k] == n) return plc::Binding{&out_[k], true, 1};
        return std::nullopt;
    }
    std::string why_unknown(std::string_view name) override {
        if (axis_number(name) >= 0) return "not an axis of this kinematics group (list it in virtual: or real:)";
        return "an inverse transform knows only ax<n>, the positions of the group's axes";
    }

    std::vector<int> virt_ids_, real_ids_;
    std::vector<double> in_, out_;
    std::unique_ptr<plc::Program> program_;
};

std::unique_ptr<motion::Inverse> compile_inverse(const config::KinematicsEntry& e, const std::string& ioc_file) {
    return std::make_unique<PlcInverse>(e, ioc_file);
}

struct IocKinematics::Group {
    config::KinematicsEntry entry;
    std::vector<std::size_t> virt, real; // IocAxes indices
    std::unique_ptr<motion::Inverse> check; // the IOC loop's copy (derived limits)
    std::vector<double> last_pose;       // pose the limits were derived at
    std::vector<motion::RealLimits> last_limits;
};

IocKinematics::IocKinematics(const config::IocConfig& cfg, IocAxes& axes, pv::Database& db)
    : axes_(axes), db_(db), file_(cfg.path) {
    std::map<int, std::size_t> index;
    for (std::size_t i = 0; i < axes.size(); ++i) index[axes.params(i).id] = i;
    std::set<int> virtual_anywhere;
    std::vector<std::string> errors;
    for (const auto& e : cfg.kinematics) {
        try {
            auto g = std::make_unique<Group>();
            g->entry = e;
            std::set<int> seen;
            auto map = [&](const std::vector<int>& ids, std::vector<std::size_t>& out, const char* what) {
                for (int id : ids) {
                    auto it = index.find(id);
                    if (it == index.end()) throw Error(SB() << e.where << ": kinematics '" << e.name << "': no axis " << id << " (" << what << ")");
                    if (!seen.insert(id).second)
                        throw Error(SB() << e.where << ": kinematics '" << e.name << "': axis " << id << " is listed twice");
                    out.push_back(it->second);
                }
            };
            map(e.virt, g->virt, "virtual");
            map(e.real, g->real, "real");
            for (int id : e.virt)
                if (!virtual_anywhere.insert(id).second)
                    throw Error(SB() << e.where << ": kinematics '" << e.name << "': axis " << id << " is a virtual axis of another group too");
            g->check = compile_inverse(e, file_);
            groups_.push_back(std::move(g));
        } catch (const plc::CompileError& ce) {
            errors.insert(errors.end(), ce.errors().begin(), ce.errors().end());
        } catch (const Error& err) {
            errors.push_back(err.what());
        }
    }
    if (errors.size() == 1) throw Error(errors.front());
    if (!errors.empty()) throw plc::CompileError(std::move(errors));
}

IocKinematics::~IocKinematics() = default;

void IocKinematics::bind() {
    motion::AxisGroup* group = axes_.group();
    if (!group) return;
    for (auto& g : groups_)
        group->add_kinematics(std::make_unique<motion::Kinematics>(
            motion::KinematicsSpec{g->entry.name, g->virt, g->real}, compile_inverse(g->entry, file_)));
}

void IocKinematics::publish() {
    for (auto& g : groups_) {
        // Derive only at rest: while a virtual axis moves, its limits stay as they were.
        bool busy = false;
        std::vector<double> pose;
        for (std::size_t i : g->virt) {
            const motion::AxisStatus& s = axes_.status(i);
            busy = busy || s.busy || !s.position_valid;
            pose.push_back(s.set_pos);
        }
        if (busy) continue;
        std::vector<motion::RealLimits> limits;
        for (std::size_t k : g->real) {
            motion::RealLimits l = motion::real_limits(axes_.params(k), axes_.status(k));
            l.switch_fwd = l.switch_bwd = false; // switches come and go: the range is the soft limits'
            limits.push_back(l);
        }
        auto same = [](const std::vector<double>& a, const std::vector<double>& b) {
            if (a.size() != b.size()) return false;
            for (std::size_t i = 0; i < a.size(); ++i)
                if (std::fabs(a[i] - b[i]) > 1e-9 * std::max(1.0, std::fabs(a[i]))) return false;
            return true;
        };
        if (same(pose, g->last_pose)) continue;
        g->last_pose = pose;
        for (std::size_t i = 0; i < g->virt.size(); ++i) {
            const motion::AxisParams& p = axes_.params(g->virt[i]);
            double lo_cfg = p.soft_bwd_enable ? p.soft_bwd : -1e9, hi_cfg = p.soft_fwd_enable ? p.soft_fwd : 1e9;
            double tol = 1e-6 * std::max(1.0, hi_cfg - lo_cfg < 1e8 ? hi_cfg - lo_cfg : 1.0);
            motion::Range r = motion::allowed_range(*g->check, pose, i, lo_cfg, hi_cfg, limits, tol);
            axes_.set_derived_limits(g->virt[i], r.lo, r.hi);
        }
    }
}

} // namespace beamctl::ioc
