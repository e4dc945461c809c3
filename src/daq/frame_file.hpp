// An area detector's frames in an HDF5 file, in the layout areaDetector's NDFileHDF5 plugin writes
// without a layout XML (its default layout), so the files read as theirs do:
//   /entry                                 NX_class="NXentry"
//   /entry/instrument                      NX_class="NXinstrument"
//   /entry/instrument/detector             NX_class="NXdetector"
//   /entry/instrument/detector/data        [frames, ny, nx] of the pixel type; NX_class="SDS",
//                                          signal=1; chunked one frame a chunk, extendible
//   /entry/instrument/NDAttributes         NX_class="NXcollection": one value a frame:
//       NDArrayUniqueId (int32), NDArrayTimeStamp (float64, s since the EPICS epoch),
//       NDArrayEpicsTSSec, NDArrayEpicsTSnSec (uint32)
//   /entry/data                            NX_class="NXdata", signal="data"
//   /entry/data/data                       a hard link to /entry/instrument/detector/data
// Threading: one thread constructs, uses and destroys a FrameFile (the area detector's file
// writer thread).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace beamctl::daq {

// A pixel's type, in areaDetector's NDDataType_t order.
enum class PixelType : uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Int64, UInt64, Float32, Float64 };

class FrameFile {
public:
    // Creates (truncates) `path` for frames of nx * ny pixels. Throws beamctl::Error naming the
    // path and HDF5's reason.
    FrameFile(const std::string& path, PixelType type, int nx, int ny);
    ~FrameFile(); // close(), errors swallowed
    FrameFile(const FrameFile&) = delete;
    FrameFile& operator=(const FrameFile&) = delete;

    // Appends one frame (nx * ny pixels of the type, row-major) and its attributes. A frame of
    // another size or type is the caller's error (Error, nothing written).
    void append(const void* pixels, PixelType type, int nx, int ny, int32_t unique_id, double timestamp);
    // Flushes and closes; idempotent. Throws Error on failure.
    void close();

    uint64_t frames() const noexcept;
    uint64_t bytes() const noexcept; // pixel bytes written
    const std::string& path() const noexcept;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace beamctl::daq
