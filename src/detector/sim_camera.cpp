#include "detector/sim_camera.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <type_traits>

namespace beamctl::detector {

const char* const kNdTypeNames[kNdTypes] = {"Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64", "Float32", "Float64"};

std::size_t nd_type_size(NdType t) noexcept {
    switch (t) {
    case NdType::Int8:
    case NdType::UInt8: return 1;
    case NdType::Int16:
    case NdType::UInt16: return 2;
    case NdType::Int32:
    case NdType::UInt32:
    case NdType::Float32: return 4;
    default: return 8;
    }
}

double nd_type_max(NdType t) noexcept {
    switch (t) {
    case NdType::Int8: return 127;
    case NdType::UInt8: return 255;
    case NdType::Int16: return 32767;
    case NdType::UInt16: return 65535;
    case NdType::Int32: return 2147483647.0;
    case NdType::UInt32: return 4294967295.0;
    case NdType::Int64: return 9.2233720368547748e18; // below 2^63: converts back exactly
    case NdType::UInt64: return 1.8446744073709550e19;
    case NdType::Float32: return std::numeric_limits<float>::max();
    default: return std::numeric_limits<double>::max();
    }
}

double nd_type_min(NdType t) noexcept {
    switch (t) {
    case NdType::Int8: return -128;
    case NdType::Int16: return -32768;
    case NdType::Int32: return -2147483648.0;
    case NdType::Int64: return -9.2233720368547748e18;
    case NdType::Float32: return -double(std::numeric_limits<float>::max());
    case NdType::Float64: return -std::numeric_limits<double>::max();
    default: return 0;
    }
}

namespace {

template <typename T> T load(const uint8_t* p) {
    T v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

// P(a <= X <= b) for X ~ N(mu, s^2) (s > 0).
double inside(double a, double b, double mu, double s) {
    if (!(b > a)) return 0;
    const double k = 1 / (s * std::sqrt(2.0));
    return std::max(0.0, (std::erfc((a - mu) * k) - std::erfc((b - mu) * k)) / 2);
}

} // namespace

double Frame::value(std::size_t i) const noexcept {
    const uint8_t* p = data.data() + i * nd_type_size(type);
    switch (type) {
    case NdType::Int8: return load<int8_t>(p);
    case NdType::UInt8: return load<uint8_t>(p);
    case NdType::Int16: return load<int16_t>(p);
    case NdType::UInt16: return load<uint16_t>(p);
    case NdType::Int32: return load<int32_t>(p);
    case NdType::UInt32: return load<uint32_t>(p);
    case NdType::Int64: return double(load<int64_t>(p));
    case NdType::UInt64: return double(load<uint64_t>(p));
    case NdType::Float32: return load<float>(p);
    case NdType::Float64: return load<double>(p);
    }
    return 0;
}

CameraSettings clip_settings(const CameraSensor& s, CameraSettings c) noexcept {
    // as ADDriver-based drivers do: binning >= 1, the region inside the sensor, at least one
    // binned pixel
    c.bin_x = std::clamp(c.bin_x, 1, s.max_x);
    c.bin_y = std::clamp(c.bin_y, 1, s.max_y);
    c.min_x = std::clamp(c.min_x, 0, s.max_x - 1);
    c.min_y = std::clamp(c.min_y, 0, s.max_y - 1);
    c.size_x = std::clamp(c.size_x, 1, s.max_x - c.min_x);
    c.size_y = std::clamp(c.size_y, 1, s.max_y - c.min_y);
    if (c.size_x < c.bin_x) c.bin_x = c.size_x;
    if (c.size_y < c.bin_y) c.bin_y = c.size_y;
    if (!(c.exposure >= 0)) c.exposure = 0;
    if (!std::isfinite(c.gain) || c.gain < 0) c.gain = 0;
    return c;
}

double Camera::normal() noexcept {
    // a table of N(0, 1) deviates (Box-Muller, made once per camera) picked by a xorshift64*
    // generator: a few ns a pixel, enough for an image's noise
    if (normals_.empty()) {
        normals_.resize(kNormals);
        for (std::size_t i = 0; i < kNormals; i += 2) {
            const double u1 = uniform(), u2 = uniform();
            const double r = std::sqrt(-2 * std::log(u1));
            normals_[i] = r * std::cos(6.283185307179586 * u2), normals_[i + 1] = r * std::sin(6.283185307179586 * u2);
        }
    }
    return normals_[std::size_t(next() >> 52) & (kNormals - 1)];
}

uint64_t Camera::next() noexcept {
    rng_ ^= rng_ >> 12, rng_ ^= rng_ << 25, rng_ ^= rng_ >> 27;
    return rng_ * 0x2545F4914F6CDD1DULL;
}

double Camera::uniform() noexcept { return (double(next() >> 11) + 0.5) * (1.0 / 9007199254740992.0); }

void Camera::render(const CameraSettings& in, const CameraSpot& spot, Frame& out) {
    const CameraSettings c = clip_settings(sensor_, in);
    const int nx = c.size_x / c.bin_x, ny = c.size_y / c.bin_y;
    const std::size_t es = nd_type_size(c.type);
    out.nx = nx, out.ny = ny, out.type = c.type;
    out.data.resize(std::size_t(nx) * std::size_t(ny) * es);
    const double ps = sensor_.pixel_size;
    const double sx = std::max(spot.sigma_x, 1e-9), sy = std::max(spot.sigma_y, 1e-9);
    // the separable profiles: the fraction of the spot in each binned column and row, the aperture
    // cutting the pixel's edges
    std::vector<double> fx(static_cast<std::size_t>(nx)), fy(static_cast<std::size_t>(ny));
    for (int i = 0; i < nx; ++i) {
        const int col = c.min_x + i * c.bin_x;
        double a = sensor_.centre_x + (col - sensor_.max_x / 2.0) * ps, b = a + c.bin_x * ps;
        a = std::max(a, spot.left), b = std::min(b, spot.right);
        fx[std::size_t(c.reverse_x ? nx - 1 - i : i)] = inside(a, b, spot.x, sx);
    }
    for (int j = 0; j < ny; ++j) {
        const int row = c.min_y + j * c.bin_y;
        double b = sensor_.centre_y + (sensor_.max_y / 2.0 - row) * ps, a = b - c.bin_y * ps;
        a = std::max(a, spot.bottom), b = std::min(b, spot.top);
        fy[std::size_t(c.reverse_y ? ny - 1 - j : j)] = inside(a, b, spot.y, sy);
    }
    const double photons = std::max(0.0, spot.flux) * sensor_.photons_per_flux * c.exposure;
    const double bins = double(c.bin_x) * double(c.bin_y);
    const double dark = sensor_.dark * bins, read = sensor_.read_noise * std::sqrt(bins);
    const Pixels px{photons, c.gain, dark, read * read, nd_type_min(c.type), nd_type_max(c.type)};
    switch (c.type) {
    case NdType::Int8: fill<int8_t>(px, fx, fy, out.data.data()); break;
    case NdType::UInt8: fill<uint8_t>(px, fx, fy, out.data.data()); break;
    case NdType::Int16: fill<int16_t>(px, fx, fy, out.data.data()); break;
    case NdType::UInt16: fill<uint16_t>(px, fx, fy, out.data.data()); break;
    case NdType::Int32: fill<int32_t>(px, fx, fy, out.data.data()); break;
    case NdType::UInt32: fill<uint32_t>(px, fx, fy, out.data.data()); break;
    case NdType::Int64: fill<int64_t>(px, fx, fy, out.data.data()); break;
    case NdType::UInt64: fill<uint64_t>(px, fx, fy, out.data.data()); break;
    case NdType::Float32: fill<float>(px, fx, fy, out.data.data()); break;
    case NdType::Float64: fill<double>(px, fx, fy, out.data.data()); break;
    }
}

// The pixels of one frame as T: gain * (e + noise) + dark, clipped to [lo, hi], rounded for integers.
template <typename T> void Camera::fill(const Pixels& p, const std::vector<double>& fx, const std::vector<double>& fy, uint8_t* out) {
    T* o = reinterpret_cast<T*>(out); // the frame's buffer: a vector<uint8_t> of nx * ny * sizeof(T)
    for (double rowf : fy) {
        const double row = p.photons * rowf;
        for (double colf : fx) {
            const double e = row * colf;
            double v = p.gain * (e + std::sqrt(e + p.read2) * normal()) + p.dark;
            v = v < p.lo ? p.lo : (v > p.hi ? p.hi : v);
            if constexpr (std::is_integral_v<T>) {
                v = std::floor(v + 0.5);
                if (v > p.hi) v = p.hi;
            }
            T x = static_cast<T>(v);
            std::memcpy(o++, &x, sizeof x);
        }
    }
}

FrameStats frame_stats(const Frame& f, double threshold, int bgd_width) {
    FrameStats s;
    const std::size_t n = std::size_t(f.nx) * std::size_t(f.ny);
    if (n == 0) return s;
    // statistics of every pixel (doComputeStatisticsT)
    std::size_t imin = 0, imax = 0;
    s.min = s.max = f.value(0);
    double sum2 = 0;
    std::vector<double> px(static_cast<std::size_t>(f.nx), 0.0), py(static_cast<std::size_t>(f.ny), 0.0); // thresholded profiles
    double m11 = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const double v = f.value(i);
        if (v < s.min) s.min = v, imin = i;
        if (v > s.max) s.max = v, imax = i;
        s.total += v;
        sum2 += v * v;
        if (v >= threshold) {
            const std::size_t ix = i % std::size_t(f.nx), iy = i / std::size_t(f.nx);
            px[ix] += v, py[iy] += v;
            m11 += v * double(ix) * double(iy);
        }
    }
    s.min_x = double(imin % std::size_t(f.nx)), s.min_y = double(imin / std::size_t(f.nx));
    s.max_x = double(imax % std::size_t(f.nx)), s.max_y = double(imax / std::size_t(f.nx));
    s.mean = s.total / double(n);
    s.sigma = std::sqrt(std::max(0.0, sum2 / double(n) - s.mean * s.mean));
    s.net = s.total;
    if (bgd_width > 0) { // the strips of that width along both edges of each dimension
        double counts = 0, pixels = 0;
        auto strip = [&](int x0, int x1, int y0, int y1) {
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x) counts += f.value(std::size_t(y) * std::size_t(f.nx) + std::size_t(x)), pixels += 1;
        };
        const int wx = std::min(bgd_width, f.nx), wy = std::min(bgd_width, f.ny);
        strip(0, wx, 0, f.ny);
        strip(f.nx - wx, f.nx, 0, f.ny);
        strip(0, f.nx, 0, wy);
        strip(0, f.nx, f.ny - wy, f.ny);
        s.net = s.total - counts / std::max(1.0, pixels) * double(n);
    }
    // centroid and moments from the thresholded profiles (doComputeCentroidT)
    double m00 = 0, m10 = 0, m20 = 0, m30 = 0, m40 = 0, m01 = 0, m02 = 0, m03 = 0, m04 = 0;
    for (std::size_t ix = 0; ix < px.size(); ++ix) {
        const double v = px[ix], x = double(ix);
        m00 += v, m10 += v * x, m20 += v * x * x, m30 += v * x * x * x, m40 += v * x * x * x * x;
    }
    for (std::size_t iy = 0; iy < py.size(); ++iy) {
        const double v = py[iy], y = double(iy);
        m01 += v * y, m02 += v * y * y, m03 += v * y * y * y, m04 += v * y * y * y * y;
    }
    if (m00 > 0) {
        const double mu20 = m20 - m10 * m10 / m00, mu02 = m02 - m01 * m01 / m00, mu11 = m11 - m10 * m01 / m00;
        const double mu30 = m30 - 3 * m10 * m20 / m00 + 2 * m10 * m10 * m10 / (m00 * m00);
        const double mu03 = m03 - 3 * m01 * m02 / m00 + 2 * m01 * m01 * m01 / (m00 * m00);
        const double mu40 = m40 - 4 * m30 * m10 / m00 + 6 * m20 * m10 * m10 / (m00 * m00) - 3 * m10 * m10 * m10 * m10 / (m00 * m00 * m00);
        const double mu04 = m04 - 4 * m03 * m01 / m00 + 6 * m02 * m01 * m01 / (m00 * m00) - 3 * m01 * m01 * m01 * m01 / (m00 * m00 * m00);
        const double vx = mu20 / m00, vy = mu02 / m00, vxy = mu11 / m00;
        s.centroid_total = m00;
        s.centroid_x = m10 / m00, s.centroid_y = m01 / m00;
        s.sigma_x = std::sqrt(std::max(0.0, vx)), s.sigma_y = std::sqrt(std::max(0.0, vy));
        if (s.sigma_x != 0 && s.sigma_y != 0) s.sigma_xy = vxy / (s.sigma_x * s.sigma_y);
        if (vx > 0) s.skew_x = mu30 / (m00 * std::pow(vx, 1.5)), s.kurtosis_x = mu40 / (m00 * vx * vx) - 3;
        if (vy > 0) s.skew_y = mu03 / (m00 * std::pow(vy, 1.5)), s.kurtosis_y = mu04 / (m00 * vy * vy) - 3;
        s.orientation = 0.5 * std::atan2(2 * vxy, vx - vy) * 180 / 3.141592653589793;
        if (mu20 + mu02 != 0) s.eccentricity = ((mu20 - mu02) * (mu20 - mu02) - 4 * mu11 * mu11) / ((mu20 + mu02) * (mu20 + mu02));
    }
    return s;
}

} // namespace beamctl::detector
