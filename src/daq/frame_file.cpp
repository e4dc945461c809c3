#include "daq/frame_file.hpp"

#include "daq/hdf5_util.hpp"

#include <cmath>

namespace beamctl::daq {
namespace {

hid_t native(PixelType t) {
    switch (t) {
    case PixelType::Int8: return H5T_NATIVE_INT8;
    case PixelType::UInt8: return H5T_NATIVE_UINT8;
    case PixelType::Int16: return H5T_NATIVE_INT16;
    case PixelType::UInt16: return H5T_NATIVE_UINT16;
    case PixelType::Int32: return H5T_NATIVE_INT32;
    case PixelType::UInt32: return H5T_NATIVE_UINT32;
    case PixelType::Int64: return H5T_NATIVE_INT64;
    case PixelType::UInt64: return H5T_NATIVE_UINT64;
    case PixelType::Float32: return H5T_NATIVE_FLOAT;
    case PixelType::Float64: return H5T_NATIVE_DOUBLE;
    }
    return H5T_NATIVE_UINT8;
}

std::size_t size_of(PixelType t) {
    switch (t) {
    case PixelType::Int8:
    case PixelType::UInt8: return 1;
    case PixelType::Int16:
    case PixelType::UInt16: return 2;
    case PixelType::Int32:
    case PixelType::UInt32:
    case PixelType::Float32: return 4;
    default: return 8;
    }
}

Handle group(hid_t parent, const char* name, const char* nx_class, const std::string& path, const std::string& where) {
    Handle g = check(H5Gcreate2(parent, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose, path, "cannot create " + where);
    string_attribute(g.get(), "NX_class", nx_class, path, where);
    return g;
}

// An extendible dataset of rank 1 (an attribute a frame) or 3 (the frames).
Handle extendible(hid_t parent, const char* name, hid_t type, int rank, const hsize_t* chunk, const std::string& path) {
    hsize_t zero[3] = {0, chunk[1], chunk[2]}, max[3] = {H5S_UNLIMITED, chunk[1], chunk[2]};
    Handle space = check(H5Screate_simple(rank, zero, max), H5Sclose, path, "dataspace");
    Handle dcpl = check(H5Pcreate(H5P_DATASET_CREATE), H5Pclose, path, "dataset creation list");
    if (H5Pset_chunk(dcpl.get(), rank, chunk) < 0) fail(path, "cannot set the chunk size");
    return check(H5Dcreate2(parent, name, type, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT), H5Dclose, path,
                 std::string("cannot create ") + name);
}

// Writes one row at index `row` of an extendible dataset (its rank's trailing dims are fixed).
void write_row(hid_t ds, hid_t mem_type, int rank, const hsize_t* row_dims, uint64_t row, const void* buf, const std::string& path) {
    hsize_t extent[3] = {row + 1, row_dims[1], row_dims[2]};
    if (H5Dset_extent(ds, extent) < 0) fail(path, "cannot extend a dataset");
    Handle file_space = check(H5Dget_space(ds), H5Sclose, path, "dataspace");
    hsize_t start[3] = {row, 0, 0}, count[3] = {1, row_dims[1], row_dims[2]};
    if (H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr) < 0) fail(path, "cannot select a row");
    Handle mem_space = check(H5Screate_simple(rank, count, nullptr), H5Sclose, path, "dataspace");
    if (H5Dwrite(ds, mem_type, mem_space.get(), file_space.get(), H5P_DEFAULT, buf) < 0) fail(path, "cannot write");
}

} // namespace

struct FrameFile::Impl {
    std::string path;
    PixelType type;
    int nx, ny;
    Handle file, data, uid, ts, sec, nsec;
    uint64_t frames = 0, bytes = 0;
    bool broken = false;
};

FrameFile::FrameFile(const std::string& path, PixelType type, int nx, int ny) : impl_(std::make_unique<Impl>()) {
    quiet_hdf5();
    if (nx < 1 || ny < 1) throw Error(SB() << path << ": a frame of " << nx << " x " << ny << " pixels");
    Impl& m = *impl_;
    m.path = path, m.type = type, m.nx = nx, m.ny = ny;
    m.file = check(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose, path, "cannot create the file");
    Handle entry = group(m.file.get(), "entry", "NXentry", path, "/entry");
    Handle inst = group(entry.get(), "instrument", "NXinstrument", path, "/entry/instrument");
    Handle det = group(inst.get(), "detector", "NXdetector", path, "/entry/instrument/detector");
    const hsize_t chunk[3] = {1, hsize_t(ny), hsize_t(nx)};
    m.data = extendible(det.get(), "data", native(type), 3, chunk, path);
    string_attribute(m.data.get(), "NX_class", "SDS", path, "/entry/instrument/detector/data");
    int_attribute(m.data.get(), "signal", 1, path, "/entry/instrument/detector/data");
    Handle attrs = group(inst.get(), "NDAttributes", "NXcollection", path, "/entry/instrument/NDAttributes");
    const hsize_t one[3] = {1024, 0, 0};
    m.uid = extendible(attrs.get(), "NDArrayUniqueId", H5T_STD_I32LE, 1, one, path);
    m.ts = extendible(attrs.get(), "NDArrayTimeStamp", H5T_IEEE_F64LE, 1, one, path);
    m.sec = extendible(attrs.get(), "NDArrayEpicsTSSec", H5T_STD_U32LE, 1, one, path);
    m.nsec = extendible(attrs.get(), "NDArrayEpicsTSnSec", H5T_STD_U32LE, 1, one, path);
    Handle nxdata = group(entry.get(), "data", "NXdata", path, "/entry/data");
    string_attribute(nxdata.get(), "signal", "data", path, "/entry/data");
    if (H5Lcreate_hard(m.file.get(), "/entry/instrument/detector/data", nxdata.get(), "data", H5P_DEFAULT, H5P_DEFAULT) < 0) fail(path, "cannot link /entry/data/data");
}

FrameFile::~FrameFile() {
    try {
        close();
    } catch (...) {
    }
}

void FrameFile::append(const void* pixels, PixelType type, int nx, int ny, int32_t unique_id, double timestamp) {
    Impl& m = *impl_;
    if (!m.file.valid()) throw Error(SB() << m.path << ": append after close");
    if (m.broken) throw Error(SB() << m.path << ": append after a failed write");
    if (type != m.type || nx != m.nx || ny != m.ny)
        throw Error(SB() << m.path << ": a frame of " << nx << " x " << ny << " differs from the file's " << m.nx << " x " << m.ny
                         << " (or its type): close the file first");
    quiet_hdf5();
    m.broken = true; // until every dataset has its row
    const hsize_t frame[3] = {1, hsize_t(ny), hsize_t(nx)}, scalar[3] = {1, 0, 0};
    write_row(m.data.get(), native(type), 3, frame, m.frames, pixels, m.path);
    const double secs = std::floor(timestamp);
    const uint32_t sec = uint32_t(secs), nsec = uint32_t((timestamp - secs) * 1e9);
    write_row(m.uid.get(), H5T_NATIVE_INT32, 1, scalar, m.frames, &unique_id, m.path);
    write_row(m.ts.get(), H5T_NATIVE_DOUBLE, 1, scalar, m.frames, &timestamp, m.path);
    write_row(m.sec.get(), H5T_NATIVE_UINT32, 1, scalar, m.frames, &sec, m.path);
    write_row(m.nsec.get(), H5T_NATIVE_UINT32, 1, scalar, m.frames, &nsec, m.path);
    m.broken = false;
    ++m.frames;
    m.bytes += uint64_t(nx) * uint64_t(ny) * size_of(type);
}

void FrameFile::close() {
    if (!impl_ || !impl_->file.valid()) return;
    Impl& m = *impl_;
    quiet_hdf5();
    bool ok = true;
    for (Handle* h : {&m.data, &m.uid, &m.ts, &m.sec, &m.nsec}) ok = h->reset() && ok;
    ok = m.file.reset() && ok;
    if (!ok) fail(m.path, "cannot close the file");
}

uint64_t FrameFile::frames() const noexcept { return impl_->frames; }
uint64_t FrameFile::bytes() const noexcept { return impl_->bytes; }
const std::string& FrameFile::path() const noexcept { return impl_->path; }

} // namespace beamctl::daq
