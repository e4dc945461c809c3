// Small pieces of HDF5's C API the daq files share (internal to src/daq): an id that closes
// itself, checked calls that throw beamctl::Error with the file and HDF5's innermost reason, and
// scalar attributes as h5py reads them back.
// Threading: HDF5's calls are serialised by the library; quiet_hdf5() is per thread.
#pragma once

#include "core/error.hpp"

#include <hdf5.h>

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::daq {

// HDF5 prints its error stack to stderr unless told not to; the setting is per thread (the
// library is built thread-safe), so every entry point calls this first.
inline void quiet_hdf5() noexcept {
    thread_local bool done = false;
    if (!done) {
        H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
        done = true;
    }
}

inline herr_t collect_error(unsigned, const H5E_error2_t* e, void* data) {
    auto& reasons = *static_cast<std::vector<std::string>*>(data);
    if (e->desc && *e->desc) reasons.emplace_back(e->desc);
    return 0;
}

// The innermost cause on the calling thread's HDF5 error stack (the outer entries only repeat
// what failed, e.g. "unable to create file"), on one line; clears the stack.
inline std::string hdf5_reason() {
    std::vector<std::string> reasons;
    H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, collect_error, &reasons);
    H5Eclear2(H5E_DEFAULT);
    if (reasons.empty()) return "unknown HDF5 error";
    std::string s = reasons.front();
    for (char& c : s)
        if (c == '\n') c = ' ';
    return s;
}

[[noreturn]] inline void fail(const std::string& path, std::string_view what) {
    throw Error(SB() << path << ": " << what << ": " << hdf5_reason());
}

// An HDF5 id closed with its own close function.
class Handle {
public:
    using Closer = herr_t (*)(hid_t);
    Handle() = default;
    Handle(hid_t id, Closer close)
        : id_(id)
        , close_(close) {}
    Handle(Handle&& o) noexcept
        : id_(o.id_)
        , close_(o.close_) {
        o.id_ = H5I_INVALID_HID;
    }
    Handle& operator=(Handle&& o) noexcept {
        if (this != &o) {
            reset();
            id_ = o.id_;
            close_ = o.close_;
            o.id_ = H5I_INVALID_HID;
        }
        return *this;
    }
    ~Handle() { reset(); }
    hid_t get() const noexcept { return id_; }
    bool valid() const noexcept { return id_ >= 0; }
    // Closes; false if HDF5 failed to (the id is gone either way).
    bool reset() noexcept {
        bool ok = true;
        if (id_ >= 0) ok = close_(id_) >= 0;
        id_ = H5I_INVALID_HID;
        return ok;
    }

private:
    hid_t id_ = H5I_INVALID_HID;
    Closer close_ = nullptr;
};

// Checks an id an HDF5 call returned; throws with the path, what and HDF5's reason.
inline Handle check(hid_t id, Handle::Closer close, const std::string& path, std::string_view what) {
    if (id < 0) fail(path, what);
    return Handle(id, close);
}

inline Handle utf8_string_type(const std::string& path) {
    Handle t = check(H5Tcopy(H5T_C_S1), H5Tclose, path, "string type");
    if (H5Tset_size(t.get(), H5T_VARIABLE) < 0 || H5Tset_cset(t.get(), H5T_CSET_UTF8) < 0)
        fail(path, "string type");
    return t;
}

// A scalar variable-length UTF-8 string attribute (what h5py reads back as str).
inline void string_attribute(hid_t obj, const std::string& name, const std::string& value,
                      const std::string& path, const std::string& where) {
    Handle type = utf8_string_type(path);
    Handle space = check(H5Screate(H5S_SCALAR), H5Sclose, path, "dataspace");
    std::string what = "attribute " + where + "@" + name;
    Handle attr =
        check(H5Acreate2(obj, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT),
              H5Aclose, path, "cannot create " + what);
    const char* p = value.c_str();
    if (H5Awrite(attr.get(), type.get(), &p) < 0) fail(path, "cannot write " + what);
}

inline void int_attribute(hid_t obj, const std::string& name, int32_t value, const std::string& path,
                   const std::string& where) {
    Handle space = check(H5Screate(H5S_SCALAR), H5Sclose, path, "dataspace");
    std::string what = "attribute " + where + "@" + name;
    Handle attr =
        check(H5Acreate2(obj, name.c_str(), H5T_STD_I32LE, space.get(), H5P_DEFAULT, H5P_DEFAULT),
              H5Aclose, path, "cannot create " + what);
    if (H5Awrite(attr.get(), H5T_NATIVE_INT32, &value) < 0) fail(path, "cannot write " + what);
}

} // namespace beamctl::daq
