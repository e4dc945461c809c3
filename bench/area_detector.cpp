// The area detector's costs (issue 16): a 1024 x 1024 UInt16 frame rendered from the beam (shot
// and read noise), its NDStats statistics with the centroid, and frames written into an HDF5 file
// in NDFileHDF5's layout (daq/frame_file.hpp) unpaced, fsync included: frames/s and MB/s, to set
// against dd's sequential write rate that bench/area_detector.sh measures in the same directory
// in the same run (target: >= 50 %).
//   bench_area_detector DIR [FRAMES=300]
#include "daq/frame_file.hpp"
#include "detector/sim_camera.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

using namespace beamctl;
using Clock = std::chrono::steady_clock;

static double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

int main(int argc, char** argv) {
    const std::string dir = argc > 1 ? argv[1] : "/tmp";
    const int frames = argc > 2 ? std::atoi(argv[2]) : 300;
    detector::CameraSensor s;
    s.max_x = s.max_y = 1024, s.pixel_size = 0.005, s.photons_per_flux = 2e10;
    detector::Camera cam(s);
    detector::CameraSettings c;
    c.size_x = c.size_y = 1024, c.type = detector::NdType::UInt16, c.exposure = 0.01;
    detector::CameraSpot spot;
    spot.sigma_x = 0.3, spot.sigma_y = 0.1, spot.flux = 1;
    detector::Frame f;
    // render
    const int n_render = 30;
    auto t0 = Clock::now();
    for (int i = 0; i < n_render; ++i) cam.render(c, spot, f);
    const double render_ms = seconds_since(t0) / n_render * 1e3;
    // statistics + centroid
    t0 = Clock::now();
    double sink = 0;
    for (int i = 0; i < n_render; ++i) sink += detector::frame_stats(f, 100, 0).centroid_x;
    const double stats_ms = seconds_since(t0) / n_render * 1e3;
    std::printf("frame 1024 x 1024 UInt16 (2 MiB): render %.2f ms, NDStats with centroid %.2f ms (centroid %.1f px)\n", render_ms, stats_ms,
                sink / n_render);
    // HDF5, unpaced, fsync included
    const std::string path = dir + "/bench_area_detector_" + std::to_string(::getpid()) + ".h5";
    t0 = Clock::now();
    {
        daq::FrameFile file(path, daq::PixelType::UInt16, 1024, 1024);
        for (int i = 0; i < frames; ++i) file.append(f.data.data(), daq::PixelType::UInt16, 1024, 1024, i + 1, 1e9 + i);
        file.close();
    }
    const int fd = ::open(path.c_str(), O_RDONLY);
    if (fd >= 0) ::fsync(fd), ::close(fd);
    const double secs = seconds_since(t0);
    const double mb = double(frames) * 1024 * 1024 * 2 / 1e6;
    std::printf("HDF5 (NDFileHDF5 layout), %d frames, fsync included: %.1f frames/s, %.0f MB/s\n", frames, frames / secs, mb / secs);
    ::unlink(path.c_str());
    return 0;
}
