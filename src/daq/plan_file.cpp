// A plan run's NeXus file, written in one go (see plan_file.hpp).
#include "daq/plan_file.hpp"

#include "core/error.hpp"
#include "daq/hdf5_util.hpp"

#include <hdf5.h>

#include <set>

namespace beamctl::daq {

namespace {

bool plain_name(const std::string& n) { return !n.empty() && n != "." && n != ".." && n.find('/') == std::string::npos; }

void double_attribute(hid_t obj, const std::string& name, double value, const std::string& path, const std::string& where) {
    Handle space = check(H5Screate(H5S_SCALAR), H5Sclose, path, "dataspace");
    const std::string what = "attribute " + where + "@" + name;
    Handle attr = check(H5Acreate2(obj, name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose, path,
                        "cannot create " + what);
    if (H5Awrite(attr.get(), H5T_NATIVE_DOUBLE, &value) < 0) fail(path, "cannot write " + what);
}

Handle group(hid_t parent, const std::string& name, const char* nx_class, const std::string& path, const std::string& where) {
    Handle g = check(H5Gcreate2(parent, name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose, path, "cannot create " + where);
    string_attribute(g.get(), "NX_class", nx_class, path, where);
    return g;
}

// Refuses a run whose names would make a broken file, before the file is touched.
void validate(const std::string& path, const PlanRun& run) {
    std::set<std::string> scans;
    for (const PlanScan& s : run.scans) {
        if (!plain_name(s.name) || !scans.insert(s.name).second)
            throw Error(SB() << path << ": scan name \"" << s.name << "\" is not a new group name under /entry");
        std::set<std::string> cols;
        for (const PlanColumn& c : s.columns) {
            if (!plain_name(c.name) || !cols.insert(c.name).second)
                throw Error(SB() << path << ": scan " << s.name << ": column name \"" << c.name << "\" is not a new dataset name");
            if (c.values.size() != s.columns[0].values.size())
                throw Error(SB() << path << ": scan " << s.name << ": column " << c.name << " has " << c.values.size()
                                 << " values, column " << s.columns[0].name << " " << s.columns[0].values.size());
        }
        for (const std::string* d : {&s.axis, &s.signal})
            if (!d->empty() && !cols.count(*d)) throw Error(SB() << path << ": scan " << s.name << ": \"" << *d << "\" is not one of its columns");
    }
}

} // namespace

void write_plan_file(const std::string& path, const PlanRun& run) {
    quiet_hdf5();
    validate(path, run);
    Handle file = check(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose, path, "cannot create the file");
    string_attribute(file.get(), "default", "entry", path, "/");
    Handle entry = group(file.get(), "entry", "NXentry", path, "/entry");
    if (!run.scans.empty()) string_attribute(entry.get(), "default", run.scans.front().name, path, "/entry");
    if (!run.title.empty()) string_attribute(entry.get(), "title", run.title, path, "/entry");
    for (const auto& [k, v] : run.attributes) string_attribute(entry.get(), k, v, path, "/entry");
    for (const PlanScan& s : run.scans) {
        const std::string where = "/entry/" + s.name;
        Handle g = group(entry.get(), s.name, "NXdata", path, where);
        if (!s.columns.empty()) {
            const std::string axis = s.axis.empty() ? s.columns.front().name : s.axis;
            const std::string signal = s.signal.empty() ? s.columns.back().name : s.signal;
            string_attribute(g.get(), "signal", signal, path, where);
            string_attribute(g.get(), "axes", axis, path, where);
            int_attribute(g.get(), axis + "_indices", 0, path, where);
        }
        if (!s.title.empty()) string_attribute(g.get(), "title", s.title, path, where);
        for (const auto& [k, v] : s.numbers) double_attribute(g.get(), k, v, path, where);
        for (const auto& [k, v] : s.texts) string_attribute(g.get(), k, v, path, where);
        for (const PlanColumn& c : s.columns) {
            const std::string dwhere = where + "/" + c.name;
            const hsize_t n = c.values.size();
            Handle space = check(H5Screate_simple(1, &n, nullptr), H5Sclose, path, "dataspace");
            Handle ds = check(H5Dcreate2(g.get(), c.name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                              H5Dclose, path, "cannot create " + dwhere);
            if (n > 0 && H5Dwrite(ds.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, c.values.data()) < 0)
                fail(path, "cannot write " + dwhere);
            if (!c.units.empty()) string_attribute(ds.get(), "units", c.units, path, dwhere);
            if (!c.source.empty()) string_attribute(ds.get(), "source", c.source, path, dwhere);
        }
    }
    if (!file.reset()) fail(path, "cannot close the file");
}

} // namespace beamctl::daq
