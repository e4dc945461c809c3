#include "daq/nexus_file.hpp"

#include "core/error.hpp"
#include "daq/hdf5_util.hpp"

#include <hdf5.h>

#include <algorithm>
#include <iterator>
#include <set>
#include <string_view>

namespace beamctl::daq {

namespace {

constexpr const char* kReserved[] = {"cycle", "time", "timestamp_ns"};

void string_dataset(hid_t group, const std::string& name, const std::string& value,
                    const std::string& path, const std::string& where) {
    Handle type = utf8_string_type(path);
    Handle space = check(H5Screate(H5S_SCALAR), H5Sclose, path, "dataspace");
    Handle ds = check(H5Dcreate2(group, name.c_str(), type.get(), space.get(), H5P_DEFAULT,
                                 H5P_DEFAULT, H5P_DEFAULT),
                      H5Dclose, path, "cannot create " + where + "/" + name);
    const char* p = value.c_str();
    if (H5Dwrite(ds.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, &p) < 0)
        fail(path, "cannot write " + where + "/" + name);
}

// Validates the columns and options before anything is created; fills in the defaults.
void validate(const std::string& path, const std::vector<NexusColumn>& columns, NexusOptions& opt) {
    if (columns.empty()) throw Error(SB() << path << ": no columns (at least one is needed)");
    if (opt.chunk_rows == 0) throw Error(SB() << path << ": chunk_rows 0 should be >= 1");
    std::set<std::string> names(std::begin(kReserved), std::end(kReserved));
    for (std::size_t i = 0; i < columns.size(); ++i) {
        const std::string& n = columns[i].name;
        auto bad = [&](const char* why) {
            return Error(SB() << path << ": column " << i << " name \"" << n << "\" " << why);
        };
        if (n.empty() || n == ".") throw bad("is not a dataset name");
        if (n.find('/') != std::string::npos) throw bad("should not contain '/'");
        for (const char* r : kReserved)
            if (n == r) throw bad("is reserved (cycle, time and timestamp_ns are always written)");
        if (!names.insert(n).second) throw bad("appears twice");
        if (columns[i].width == 0) throw bad("has width 0 (at least one value a row)");
    }
    std::set<std::string> logs{"data", "title"};
    for (const NexusLog& l : opt.logs)
        if (l.name.empty() || l.name == "." || l.name.find('/') != std::string::npos || !logs.insert(l.name).second)
            throw Error(SB() << path << ": log name \"" << l.name << "\" is not a new group name under /entry");
    std::set<std::string> attributes{"NX_class", "default"};
    for (const auto& [name, value] : opt.attributes)
        if (name.empty() || !attributes.insert(name).second)
            throw Error(SB() << path << ": /entry attribute \"" << name << "\" "
                             << (name.empty() ? "has no name" : "is given twice or reserved"));
    if (opt.axis.empty()) opt.axis = columns[0].name;
    if (opt.signal.empty()) opt.signal = columns[columns.size() > 1 ? 1 : 0].name;
    if (!names.count(opt.axis))
        throw Error(SB() << path << ": axis \"" << opt.axis
                         << "\" is not a dataset of /entry/data");
    if (!names.count(opt.signal))
        throw Error(SB() << path << ": signal \"" << opt.signal
                         << "\" is not a dataset of /entry/data");
}

} // namespace

struct NexusFile::Impl {
    std::string path;
    std::size_t ncol = 0;     // values a row
    // per column (dataset): uint64 bit patterns in the doubles, its first value in a row, width
    std::vector<bool> uint64;
    std::vector<std::size_t> offset, width;
    Handle file;
    // Columns 0..columns-1, then cycle, time, timestamp_ns.
    std::vector<Handle> datasets;
    std::uint64_t rows = 0;
    std::uint64_t t0_ns = 0; // timestamp of the first row
    bool broken = false;     // a write failed: the datasets may differ in length
    // Reused across appends: the values column by column (ncol x capacity), the times [s].
    std::vector<double> by_column;
    std::vector<double> time_s;
    std::size_t capacity_rows = 0;

    // The logs: their first dataset (value, time, cycle, timestamp_ns follow) and rows.
    struct Log {
        std::size_t first = 0;
        std::uint64_t rows = 0, t0_ns = 0;
    };
    std::vector<Log> logs;

    // n rows of dataset k after its first `at` (w values each, row-major in buf).
    void write(std::size_t k, hsize_t at, hid_t mem_type, const void* buf, hsize_t n, hsize_t w = 1);
};

void NexusFile::Impl::write(std::size_t k, hsize_t at, hid_t mem_type, const void* buf, hsize_t n, hsize_t w) {
    hid_t ds = datasets[k].get();
    const int rank = w > 1 ? 2 : 1;
    const hsize_t new_extent[2] = {at + n, w}, start[2] = {at, 0}, count[2] = {n, w};
    if (H5Dset_extent(ds, new_extent) < 0) fail(path, "cannot extend a dataset");
    Handle file_space = check(H5Dget_space(ds), H5Sclose, path, "dataspace");
    if (H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr) < 0)
        fail(path, "cannot select rows");
    Handle mem_space = check(H5Screate_simple(rank, count, nullptr), H5Sclose, path, "dataspace");
    if (H5Dwrite(ds, mem_type, mem_space.get(), file_space.get(), H5P_DEFAULT, buf) < 0)
        fail(path, "cannot write rows");
}

NexusFile::NexusFile(const std::string& path, std::vector<NexusColumn> columns, NexusOptions opt)
    : impl_(std::make_unique<Impl>()) {
    Impl& m = *impl_;
    m.path = path;
    validate(path, columns, opt);
    for (const NexusColumn& c : columns) {
        m.uint64.push_back(c.uint64);
        m.offset.push_back(m.ncol);
        m.width.push_back(c.width);
        m.ncol += c.width;
    }
    quiet_hdf5();

    // SWMR needs the latest file format (checksummed metadata, extensible-array chunk index).
    Handle fapl = check(H5Pcreate(H5P_FILE_ACCESS), H5Pclose, path, "file access list");
    if (H5Pset_libver_bounds(fapl.get(), H5F_LIBVER_LATEST, H5F_LIBVER_LATEST) < 0)
        fail(path, "cannot ask for the latest file format");
    m.file = check(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.get()), H5Fclose, path,
                   "cannot create the file");
    // On failure below, the handles close and the partial file stays (H5Fcreate truncated it).
    string_attribute(m.file.get(), "default", "entry", path, "/");

    Handle entry = check(H5Gcreate2(m.file.get(), "entry", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                         H5Gclose, path, "cannot create /entry");
    string_attribute(entry.get(), "NX_class", "NXentry", path, "/entry");
    string_attribute(entry.get(), "default", "data", path, "/entry");
    for (const auto& [name, value] : opt.attributes)
        string_attribute(entry.get(), name, value, path, "/entry");
    if (!opt.title.empty()) string_dataset(entry.get(), "title", opt.title, path, "/entry");

    Handle data = check(H5Gcreate2(entry.get(), "data", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                        H5Gclose, path, "cannot create /entry/data");
    string_attribute(data.get(), "NX_class", "NXdata", path, "/entry/data");
    string_attribute(data.get(), "signal", opt.signal, path, "/entry/data");
    string_attribute(data.get(), "axes", opt.axis, path, "/entry/data");
    int_attribute(data.get(), opt.axis + "_indices", 0, path, "/entry/data");

    // Empty, growing without limit in rows, chunk_rows rows a chunk (of a [rows, w] dataset
    // chunk_rows / w rows: every chunk the same size, within HDF5's default 1 MiB chunk cache).
    // A dataset `name` of the group `data` holds (at `group`, for messages).
    std::string group = "/entry/data";
    auto dataset = [&](const std::string& name, hid_t type, hsize_t w = 1) {
        const std::string where = group + "/" + name;
        const int rank = w > 1 ? 2 : 1;
        const hsize_t zero[2] = {0, w}, max[2] = {H5S_UNLIMITED, w},
                      chunk[2] = {std::max<hsize_t>(1, opt.chunk_rows / w), w};
        Handle space = check(H5Screate_simple(rank, zero, max), H5Sclose, path, "dataspace");
        Handle dcpl = check(H5Pcreate(H5P_DATASET_CREATE), H5Pclose, path, "dataset creation list");
        if (H5Pset_chunk(dcpl.get(), rank, chunk) < 0) fail(path, "cannot set the chunk size");
        m.datasets.push_back(check(H5Dcreate2(data.get(), name.c_str(), type, space.get(),
                                              H5P_DEFAULT, dcpl.get(), H5P_DEFAULT),
                                   H5Dclose, path, "cannot create " + where));
        return m.datasets.back().get();
    };
    for (const NexusColumn& c : columns) {
        const std::string where = "/entry/data/" + c.name;
        hid_t ds = dataset(c.name, c.uint64 ? H5T_STD_U64LE : H5T_IEEE_F64LE, c.width);
        if (!c.units.empty()) string_attribute(ds, "units", c.units, path, where);
        string_attribute(ds, "source", c.source, path, where);
        string_attribute(ds, "capture_mode", c.mode, path, where);
        if (c.width > 1) int_attribute(ds, "samples_per_row", int32_t(c.width), path, where);
    }
    dataset("cycle", H5T_STD_U64LE);
    string_attribute(dataset("time", H5T_IEEE_F64LE), "units", "s", path, "/entry/data/time");
    string_attribute(dataset("timestamp_ns", H5T_STD_U64LE), "units", "ns", path,
                     "/entry/data/timestamp_ns");
    data.reset();
    for (const NexusLog& l : opt.logs) {
        const std::string where = group = "/entry/" + l.name;
        data = check(H5Gcreate2(entry.get(), l.name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                     H5Gclose, path, "cannot create " + where);
        string_attribute(data.get(), "NX_class", "NXlog", path, where);
        string_attribute(data.get(), "source", l.source, path, where);
        m.logs.push_back({m.datasets.size()});
        hid_t v = dataset("value", H5T_IEEE_F64LE);
        if (!l.units.empty()) string_attribute(v, "units", l.units, path, where + "/value");
        string_attribute(dataset("time", H5T_IEEE_F64LE), "units", "s", path, where + "/time");
        dataset("cycle", H5T_STD_U64LE);
        string_attribute(dataset("timestamp_ns", H5T_STD_U64LE), "units", "ns", path, where + "/timestamp_ns");
        data.reset();
    }

    // No attribute may be open here; groups and datasets may.
    entry.reset();
    data.reset();
    if (H5Fstart_swmr_write(m.file.get()) < 0) fail(path, "cannot start SWMR writing");
}

NexusFile::~NexusFile() {
    try {
        close();
    } catch (...) {
    }
}

NexusFile::NexusFile(NexusFile&&) noexcept = default;
NexusFile& NexusFile::operator=(NexusFile&& o) noexcept {
    if (this != &o) {
        try {
            close();
        } catch (...) {
        }
        impl_ = std::move(o.impl_);
    }
    return *this;
}

void NexusFile::append(const uint64_t* cycle, const uint64_t* t_ns, const double* values,
                       std::size_t n) {
    if (!impl_) throw Error("append on a moved-from NexusFile");
    Impl& m = *impl_;
    if (!m.file.valid()) throw Error(SB() << m.path << ": append after close");
    if (m.broken) throw Error(SB() << m.path << ": append after a failed write");
    if (n == 0) return;
    quiet_hdf5();
    if (m.rows == 0) m.t0_ns = t_ns[0];
    if (n > m.capacity_rows) {
        m.by_column.resize(n * m.ncol);
        m.time_s.resize(n);
        m.capacity_rows = n;
    }
    // Row-major in, one contiguous run per dataset out (the dataset whose first value is at
    // offset o of a row, width w, at o * n: n rows of w); one pass over the input with a
    // sequential output stream per dataset.
    const std::size_t ncol = m.ncol, nds = m.width.size();
    double* out = m.by_column.data();
    for (std::size_t i = 0; i < n; ++i) {
        const double* row = values + i * ncol;
        for (std::size_t d = 0; d < nds; ++d) {
            const std::size_t o = m.offset[d], w = m.width[d];
            for (std::size_t k = 0; k < w; ++k) out[o * n + i * w + k] = row[o + k];
        }
    }
    for (std::size_t i = 0; i < n; ++i) m.time_s[i] = double(int64_t(t_ns[i] - m.t0_ns)) * 1e-9;

    const hsize_t rows = n;
    m.broken = true; // until every dataset has its rows
    for (std::size_t d = 0; d < nds; ++d) // a uint64 column: the doubles' bytes are its values
        m.write(d, m.rows, m.uint64[d] ? H5T_NATIVE_UINT64 : H5T_NATIVE_DOUBLE, out + m.offset[d] * n, rows, m.width[d]);
    m.write(nds, m.rows, H5T_NATIVE_UINT64, cycle, rows);
    m.write(nds + 1, m.rows, H5T_NATIVE_DOUBLE, m.time_s.data(), rows);
    m.write(nds + 2, m.rows, H5T_NATIVE_UINT64, t_ns, rows);
    m.rows += n;
    m.broken = false;
}

void NexusFile::append_log(std::size_t k, const uint64_t* cycle, const uint64_t* t_ns, const double* values, std::size_t n) {
    if (!impl_) throw Error("append_log on a moved-from NexusFile");
    Impl& m = *impl_;
    if (!m.file.valid()) throw Error(SB() << m.path << ": append after close");
    if (m.broken) throw Error(SB() << m.path << ": append after a failed write");
    if (k >= m.logs.size()) throw Error(SB() << m.path << ": no log " << k);
    if (n == 0) return;
    quiet_hdf5();
    Impl::Log& l = m.logs[k];
    if (l.rows == 0) l.t0_ns = t_ns[0];
    if (n > m.time_s.size()) m.time_s.resize(n);
    for (std::size_t i = 0; i < n; ++i) m.time_s[i] = double(int64_t(t_ns[i] - l.t0_ns)) * 1e-9;
    m.broken = true;
    m.write(l.first, l.rows, H5T_NATIVE_DOUBLE, values, n);
    m.write(l.first + 1, l.rows, H5T_NATIVE_DOUBLE, m.time_s.data(), n);
    m.write(l.first + 2, l.rows, H5T_NATIVE_UINT64, cycle, n);
    m.write(l.first + 3, l.rows, H5T_NATIVE_UINT64, t_ns, n);
    l.rows += n;
    m.broken = false;
}

std::uint64_t NexusFile::log_rows(std::size_t k) const noexcept {
    return impl_ && k < impl_->logs.size() ? impl_->logs[k].rows : 0;
}

void NexusFile::flush() {
    if (!impl_) throw Error("flush on a moved-from NexusFile");
    Impl& m = *impl_;
    if (!m.file.valid()) throw Error(SB() << m.path << ": flush after close");
    quiet_hdf5();
    for (const Handle& d : m.datasets)
        if (H5Dflush(d.get()) < 0) fail(m.path, "cannot flush");
}

void NexusFile::close() {
    if (!impl_ || !impl_->file.valid()) return;
    Impl& m = *impl_;
    quiet_hdf5();
    std::string err;
    for (const Handle& d : m.datasets)
        if (err.empty() && H5Dflush(d.get()) < 0) err = "cannot flush: " + hdf5_reason();
    bool ok = true;
    for (Handle& d : m.datasets) ok = d.reset() && ok;
    m.datasets.clear();
    ok = m.file.reset() && ok;
    if (!ok && err.empty()) err = "cannot close: " + hdf5_reason();
    if (!err.empty()) throw Error(SB() << m.path << ": " << err);
}

std::uint64_t NexusFile::rows() const noexcept {
    return impl_ ? impl_->rows : 0;
}
std::uint64_t NexusFile::bytes() const noexcept {
    if (!impl_) return 0;
    std::uint64_t b = impl_->rows * 8 * (impl_->ncol + 3);
    for (const Impl::Log& l : impl_->logs) b += l.rows * 8 * 4;
    return b;
}
const std::string& NexusFile::path() const noexcept {
    static const std::string none;
    return impl_ ? impl_->path : none;
}
std::size_t NexusFile::columns() const noexcept {
    return impl_ ? impl_->ncol : 0;
}
bool NexusFile::is_open() const noexcept {
    return impl_ && impl_->file.valid();
}

} // namespace beamctl::daq
