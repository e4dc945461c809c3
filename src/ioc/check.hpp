// `beamctl check ioc.yaml`: every error of the IOC file and of every file it names, at once.
// Configuration-time code; one thread.
#pragma once

#include "core/macros.hpp"

#include <cstddef>
#include <cstdio>
#include <string>
#include <vector>

namespace beamctl::ioc {

struct CheckReport {
    std::vector<std::string> errors; // "file:line:col: what", the IOC file's first, then by file
    std::vector<std::string> warnings; // of the ECMC axis and encoder files (unknown keys, ...)
    std::size_t pvs = 0, buses = 0;  // of the IOC built from the files (when there is no error)
    bool ok() const { return errors.empty(); }
};

// Reads the IOC file (its text expanded with `macros` as `beamctl run -m` does) and then each
// file it names with every error of each: axis and encoder files, plant files (also against the
// bus's slaves), PLC files (compiled, names of every known namespace accepted), kinematics files,
// .db files (parsed and loaded), plugins and the ACF. A file that cannot be read is an error at
// the place in the IOC file that names it ("ioc.yaml:23:5: axes[2].file: <path>: No such file or
// directory"); an unknown slave type lists the catalog's close matches. When every file is
// correct, the IOC is built as `beamctl run` builds it (nothing started) for the errors between
// files: signal names of axes, PLC bindings, kinematics.
CheckReport check_ioc(const std::string& path, const MacroMap& macros = {});

// check_ioc, printed: each warning ("warning: ...") and error on `err`, then
// "<path>: OK (N PVs, M bus(es))" on `out` when there is no error.
// Returns the exit code of `beamctl check`: 0, or 1 with errors.
int run_check(const std::string& path, const MacroMap& macros = {}, std::FILE* out = stdout,
              std::FILE* err = stderr);

// `beamctl axis check`: one ECMC axis file on its own, as loadYamlAxis.cmd takes it (with the
// encoder files of loadYamlEnc.cmd after it), without an IOC: every error of the files, what
// the runtime cannot do (make_axis_params), and the axis PLC compiled with every well-formed
// name accepted (as `beamctl plc check` without --ioc). Signal names are checked for syntax only
// (the IOC checks them against its buses). Prints the warnings and "<file>: OK" on `out`, the
// errors on `err`; returns 0, or 1 with errors.
int run_axis_check(const std::string& file, const std::vector<std::string>& encoder_files,
                   const MacroMap& macros, std::FILE* out = stdout, std::FILE* err = stderr);

} // namespace beamctl::ioc
