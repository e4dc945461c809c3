// The IOC's kinematics groups (`kinematics:` in ioc.yaml; motion/kinematics.hpp): each inverse
// transform is compiled from the PLC language when the IOC is built (errors with file:line:col,
// `beamctl check` reports them), handed to the axis group's RT checks at bring-up, and used on the
// IOC loop to derive the virtual axes' soft limits from the real axes' ones, which the virtual
// motor records then carry (DHLM/DLLM, and HLM/LLM through the record's calibration).
// Threading: everything here on the IOC loop thread, except the RT copy of each transform, which
// only the axis group's stage uses.
#pragma once

#include "config/ioc_config.hpp"
#include "ioc/axes.hpp"
#include "motion/kinematics.hpp"
#include "pv/database.hpp"

#include <memory>
#include <string>
#include <vector>

namespace beamctl::ioc {

// An inverse transform compiled from PLC code: `ax<n>` names the position of axis n, read for
// the group's virtual axes and assigned for its real axes.
// Throws plc::CompileError (every error) or Error.
std::unique_ptr<motion::Inverse> compile_inverse(const config::KinematicsEntry& e, const std::string& ioc_file);

class IocKinematics {
public:
    // Checks the groups against the axes (ids exist, no axis twice, an axis virtual in one group
    // at most) and compiles every transform. Throws Error (every compile error of a transform).
    IocKinematics(const config::IocConfig& cfg, IocAxes& axes, pv::Database& db);
    ~IocKinematics();
    // Bring-up, after the axes are bound: the groups join the axis group's RT checks.
    void bind();
    // IOC loop: derived soft limits into the virtual motor records (when the poses change).
    void publish();
    std::size_t size() const { return groups_.size(); }

private:
    struct Group;
    IocAxes& axes_;
    pv::Database& db_;
    std::string file_;
    std::vector<std::unique_ptr<Group>> groups_;
};

} // namespace beamctl::ioc
