// A plan run's file (docs/automation.md): HDF5 (C API) in a NeXus layout, written once, when the
// run ends (a plan's points are few; the live data is on the plan's waveform PVs meanwhile).
//
// Layout:
//   /                    default="entry"
//   /entry               NX_class="NXentry", default=<first scan>, title, string attributes (plan,
//                        args, status, message, start_time, end_time, ioc)
//   /entry/<scan>        NX_class="NXdata", signal, axes, <axes>_indices=0, title, and the
//                        scan's results as attributes (fit_center, fit_center_err, ...: float64;
//                        fit_model, fit_check: strings)
//   /entry/<scan>/<column>  float64 [points], units (if any), source (the PV)
//
// Threading: any one thread at a time (HDF5 serialises its calls in the process).
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace beamctl::daq {

struct PlanColumn {
    std::string name;   // dataset name: no '/', not "." nor ".."
    std::string units;  // "deg"; no attribute if empty
    std::string source; // the PV it was read from; no attribute if empty
    std::vector<double> values;
};

struct PlanScan {
    std::string name;   // group under /entry: no '/'
    std::string title;  // what the scan was ("align_t1_th1 pass 1/2: SND:T1:TH1 23.75 .. 23.85")
    std::string axis, signal; // datasets of the scan (default: the first and the last column)
    std::vector<PlanColumn> columns;  // all of one length (the points taken)
    std::vector<std::pair<std::string, double>> numbers;     // float64 attributes
    std::vector<std::pair<std::string, std::string>> texts;  // string attributes
};

struct PlanRun {
    std::string title;
    std::vector<std::pair<std::string, std::string>> attributes; // on /entry
    std::vector<PlanScan> scans;
};

// Creates (truncates) `path` and writes the run. Throws beamctl::Error naming the path and
// HDF5's reason (or the column that is wrong) before or while writing.
void write_plan_file(const std::string& path, const PlanRun& run);

} // namespace beamctl::daq
