// A simulated area detector (a beam-viewing camera) and the arithmetic of areaDetector's NDStats
// plugin on its frames.
//
// The camera images a Gaussian spot at the beam plane: sensor pixel (column c, row r) covers
//   x in centre_x + (c - max_x/2) * pixel_size + [0, pixel_size]        (c = 0 at the left)
//   y in centre_y + (max_y/2 - r) * pixel_size - [0, pixel_size]        (r = 0 at the top)
// [mm]. A frame is the region MinX, MinY, SizeX, SizeY of the sensor (sensor pixels) binned
// BinX x BinY, optionally reversed, as areaDetector's ADBase defines them. A pixel's value is
//   gain * (e + shot noise + read noise) + dark,   e = photons * (fraction of the spot in it)
// with the spot's x/y profiles blurred by its motion during the exposure (variance added), the
// slit's aperture cutting it, shot noise Gaussian with variance e, then clipped to the data type's
// range (saturation) and rounded for integer types.
// Threading: render() and stats() on any thread; a Camera's state (its noise generator) on one.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace beamctl::detector {

// areaDetector's NDDataType_t, in its order (the DataType menu's values).
enum class NdType : uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Int64, UInt64, Float32, Float64 };
constexpr int kNdTypes = 10;
extern const char* const kNdTypeNames[kNdTypes]; // "Int8" .. "Float64"
std::size_t nd_type_size(NdType t) noexcept;
double nd_type_max(NdType t) noexcept; // the largest value a pixel holds (saturation)
double nd_type_min(NdType t) noexcept;

// The camera as built (configuration).
struct CameraSensor {
    int max_x = 640, max_y = 480;   // sensor pixels (MaxSizeX/Y_RBV)
    double pixel_size = 0.005;      // [mm] at the beam plane
    double centre_x = 0, centre_y = 0; // beam-plane point at the sensor's centre [mm]
    double photons_per_flux = 1e10; // photo-electrons per second per flux unit of the beam
    double dark = 10;               // counts a sensor pixel per frame at any gain (offset)
    double read_noise = 2;          // electrons rms a sensor pixel per frame
};

// What the IOC's PVs set for a frame.
struct CameraSettings {
    double exposure = 0.01; // [s] AcquireTime
    double gain = 1;        // counts per electron (Gain)
    int bin_x = 1, bin_y = 1, min_x = 0, min_y = 0, size_x = 640, size_y = 480;
    bool reverse_x = false, reverse_y = false;
    NdType type = NdType::UInt16;
};

// The spot during one exposure (beam-plane coordinates, mm).
struct CameraSpot {
    double x = 0, y = 0;               // mean centre
    double sigma_x = 0.1, sigma_y = 0.1; // size, motion blur included
    double flux = 0;                   // mean flux through the slit (flux units)
    double left = -1e300, right = 1e300, bottom = -1e300, top = 1e300; // the slit's aperture
};

// A frame: nx * ny pixels of `type`, row-major from the top-left; `unique_id` counts frames.
struct Frame {
    int nx = 0, ny = 0;
    NdType type = NdType::UInt16;
    std::vector<uint8_t> data;
    int64_t unique_id = 0;
    double timestamp = 0; // [s] since the EPICS epoch (areaDetector's NDArray timeStamp)
    double value(std::size_t i) const noexcept; // pixel i as a double
};

// The frame's size after region clipping and binning (settings corrected to the sensor: what
// the _RBV PVs show). Returns the corrected settings.
CameraSettings clip_settings(const CameraSensor& s, CameraSettings c) noexcept;

class Camera {
public:
    explicit Camera(CameraSensor s, uint64_t seed = 0x5eed) : sensor_(s), rng_(seed | 1) {}
    const CameraSensor& sensor() const { return sensor_; }
    // Renders a frame of `c` (clipped by clip_settings) into `out` (its buffer reused).
    void render(const CameraSettings& c, const CameraSpot& spot, Frame& out);

private:
    struct Pixels {
        double photons, gain, dark, read2, lo, hi;
    };
    template <typename T> void fill(const Pixels& p, const std::vector<double>& fx, const std::vector<double>& fy, uint8_t* out);
    double normal() noexcept; // N(0, 1)
    double uniform() noexcept; // (0, 1)
    uint64_t next() noexcept;
    static constexpr std::size_t kNormals = 4096;
    CameraSensor sensor_;
    uint64_t rng_;
    std::vector<double> normals_;
};

// NDStats' results (NDPluginStats: doComputeStatistics, doComputeCentroid), pixel coordinates of
// the frame (binned pixels, 0 at the top-left).
struct FrameStats {
    double min = 0, max = 0, mean = 0, sigma = 0, total = 0, net = 0;
    double min_x = 0, min_y = 0, max_x = 0, max_y = 0;
    double centroid_total = 0, centroid_x = 0, centroid_y = 0, sigma_x = 0, sigma_y = 0, sigma_xy = 0;
    double skew_x = 0, skew_y = 0, kurtosis_x = 0, kurtosis_y = 0, eccentricity = 0, orientation = 0;
};

// Statistics of `f`: every pixel; the centroid and moments from the pixels >= `threshold`;
// `bgd_width` > 0: net = total - the mean of a border that wide times the pixel count.
FrameStats frame_stats(const Frame& f, double threshold, int bgd_width);

} // namespace beamctl::detector
