// The simulated camera and NDStats' arithmetic: the spot lands where the geometry says, binning,
// region, reversal, the slit's edges, gain, saturation and noise do what ADCore users expect, and
// the statistics are NDPluginStats' (checked by hand on small frames).
#include "detector/sim_camera.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

using namespace beamctl::detector;

namespace {

// A quiet camera (no dark, no read noise) of 200 x 100 pixels of 10 um around the origin.
CameraSensor quiet() {
    CameraSensor s;
    s.max_x = 200, s.max_y = 100, s.pixel_size = 0.01, s.dark = 0, s.read_noise = 0, s.photons_per_flux = 1e9;
    return s;
}

CameraSettings full(const CameraSensor& s) {
    CameraSettings c;
    c.size_x = s.max_x, c.size_y = s.max_y, c.exposure = 0.01, c.type = NdType::Float64;
    return c;
}

} // namespace

TEST(SimCamera, TheSpotLandsWhereTheGeometrySays) {
    Camera cam(quiet());
    CameraSpot spot;
    spot.x = 0.2, spot.y = 0.1, spot.sigma_x = 0.05, spot.sigma_y = 0.03, spot.flux = 1;
    Frame f;
    cam.render(full(cam.sensor()), spot, f);
    ASSERT_EQ(f.nx, 200);
    ASSERT_EQ(f.ny, 100);
    const FrameStats s = frame_stats(f, -1e300, 0);
    // column c's centre is x = (c - 100 + 0.5) * 10 um, row r's is y = (50 - r - 0.5) * 10 um
    EXPECT_NEAR(s.centroid_x, 100 - 0.5 + 20, 0.05);
    EXPECT_NEAR(s.centroid_y, 50 - 0.5 - 10, 0.05);
    // pixel integration adds 1/12 pixel^2 to the variance
    EXPECT_NEAR(s.sigma_x, std::sqrt(25.0 + 1.0 / 12), 0.05);
    EXPECT_NEAR(s.sigma_y, std::sqrt(9.0 + 1.0 / 12), 0.05);
    // photons * the whole spot (shot noise: sqrt of 1e7 is 0.03 %)
    EXPECT_NEAR(s.total, 1e9 * 0.01, 1e9 * 0.01 * 0.002);
    EXPECT_EQ(s.max_x, 120);
    EXPECT_NEAR(s.sigma_xy, 0, 0.01);
}

TEST(SimCamera, BinningRegionAndReversal) {
    Camera cam(quiet());
    CameraSpot spot;
    spot.x = 0.2, spot.y = 0.1, spot.sigma_x = 0.05, spot.sigma_y = 0.03, spot.flux = 1;
    CameraSettings c = full(cam.sensor());
    c.bin_x = 2, c.bin_y = 4;
    Frame f;
    cam.render(c, spot, f);
    EXPECT_EQ(f.nx, 100);
    EXPECT_EQ(f.ny, 25);
    FrameStats s = frame_stats(f, -1e300, 0);
    EXPECT_NEAR(s.centroid_x, (119.5 + 0.5) / 2 - 0.5, 0.05);
    EXPECT_NEAR(s.centroid_y, (39.5 + 0.5) / 4 - 0.5, 0.05);
    // a region: columns 100..149, rows 20..59 of the sensor
    c = full(cam.sensor());
    c.min_x = 100, c.size_x = 50, c.min_y = 20, c.size_y = 40;
    cam.render(c, spot, f);
    EXPECT_EQ(f.nx, 50);
    EXPECT_EQ(f.ny, 40);
    s = frame_stats(f, -1e300, 0);
    EXPECT_NEAR(s.centroid_x, 19.5, 0.05);
    EXPECT_NEAR(s.centroid_y, 19.5, 0.05);
    // reversed in x: mirrored about the region's centre
    c.reverse_x = true;
    cam.render(c, spot, f);
    EXPECT_NEAR(frame_stats(f, -1e300, 0).centroid_x, 49 - 19.5, 0.05);
    // a region outside the sensor is clipped to it, as the _RBV PVs then show
    c = full(cam.sensor());
    c.min_x = 190, c.size_x = 50, c.bin_x = 0;
    const CameraSettings k = clip_settings(cam.sensor(), c);
    EXPECT_EQ(k.min_x, 190);
    EXPECT_EQ(k.size_x, 10);
    EXPECT_EQ(k.bin_x, 1);
}

TEST(SimCamera, TheSlitCutsTheSpotAtItsEdges) {
    Camera cam(quiet());
    CameraSpot spot;
    spot.sigma_x = 0.05, spot.sigma_y = 0.05, spot.flux = 1;
    Frame f;
    cam.render(full(cam.sensor()), spot, f);
    const double whole = frame_stats(f, -1e300, 0).total;
    spot.top = 0; // the upper half is cut off: only rows below the centre (r >= 50) see light
    cam.render(full(cam.sensor()), spot, f);
    FrameStats s = frame_stats(f, -1e300, 0);
    EXPECT_NEAR(s.total / whole, 0.5, 0.002);
    for (int r = 0; r < 50; ++r) EXPECT_EQ(f.value(std::size_t(r) * 200 + 100), 0.0) << r;
    EXPECT_GT(f.value(50 * 200 + 100), 0.0);
}

TEST(SimCamera, GainSaturationNoiseAndPixelTypes) {
    CameraSensor sn = quiet();
    sn.dark = 100, sn.read_noise = 5;
    Camera cam(sn);
    CameraSpot spot; // no beam: the dark level and the read noise only
    spot.flux = 0;
    CameraSettings c = full(sn);
    c.type = NdType::UInt16;
    Frame f;
    cam.render(c, spot, f);
    EXPECT_EQ(f.data.size(), 200u * 100 * 2);
    FrameStats s = frame_stats(f, -1e300, 0);
    EXPECT_NEAR(s.mean, 100, 0.2);
    EXPECT_NEAR(s.sigma, 5, 0.2); // rounding adds 1/12 count^2
    // gain 2: the noise doubles, the dark stays (an offset)
    c.gain = 2;
    cam.render(c, spot, f);
    s = frame_stats(f, -1e300, 0);
    EXPECT_NEAR(s.mean, 100, 0.2);
    EXPECT_NEAR(s.sigma, 10, 0.3);
    // a bright spot saturates a UInt8 frame at 255, and a UInt16 one at 65535
    spot.flux = 1e3, spot.sigma_x = spot.sigma_y = 0.05;
    c.type = NdType::UInt8;
    cam.render(c, spot, f);
    EXPECT_EQ(f.data.size(), 200u * 100);
    EXPECT_EQ(frame_stats(f, -1e300, 0).max, 255);
    c.type = NdType::UInt16;
    cam.render(c, spot, f);
    EXPECT_EQ(frame_stats(f, -1e300, 0).max, 65535);
    c.type = NdType::Int16;
    cam.render(c, spot, f);
    EXPECT_EQ(frame_stats(f, -1e300, 0).max, 32767);
    // shot noise: a flat 10000-electron field has a 100-electron spread
    CameraSensor flat = quiet();
    flat.max_x = flat.max_y = 100, flat.pixel_size = 0.001;
    Camera fc(flat);
    CameraSpot wide;
    wide.sigma_x = wide.sigma_y = 100, wide.flux = 1; // 100 mm: flat over 0.1 mm
    CameraSettings fs = full(flat);
    fs.exposure = 1;
    // electrons a pixel: 1e9 * (1 um / (sqrt(2 pi) 100 mm))^2 per ... scale the flux to 10000
    const double per_pixel = 1e9 * std::pow(0.001 / (std::sqrt(2 * M_PI) * 100), 2);
    wide.flux = 10000 / per_pixel;
    fc.render(fs, wide, f);
    s = frame_stats(f, -1e300, 0);
    EXPECT_NEAR(s.mean, 10000, 5);
    EXPECT_NEAR(s.sigma, 100, 3);
}

TEST(SimCamera, StatisticsAreNdPluginStats) {
    // a 4 x 3 frame by hand
    Frame f;
    f.nx = 4, f.ny = 3, f.type = NdType::Float64;
    const double v[12] = {0, 1, 0, 0, //
                          1, 5, 2, 0, //
                          0, 1, 0, 9};
    f.data.resize(sizeof v);
    std::memcpy(f.data.data(), v, sizeof v);
    FrameStats s = frame_stats(f, 1, 0);
    EXPECT_EQ(s.total, 19);
    EXPECT_EQ(s.min, 0);
    EXPECT_EQ(s.max, 9);
    EXPECT_EQ(s.max_x, 3);
    EXPECT_EQ(s.max_y, 2);
    EXPECT_EQ(s.min_x, 0);
    EXPECT_EQ(s.min_y, 0);
    EXPECT_NEAR(s.mean, 19.0 / 12, 1e-12);
    double sq = 0;
    for (double x : v) sq += x * x;
    EXPECT_NEAR(s.sigma, std::sqrt(sq / 12 - s.mean * s.mean), 1e-12);
    // centroid over the pixels >= 1: x moments (1*1 + 1*0 + 5*1 + 2*2 + 1*1 + 9*3) / 19
    EXPECT_NEAR(s.centroid_total, 19, 1e-12);
    EXPECT_NEAR(s.centroid_x, (1 + 0 + 5 + 4 + 1 + 27) / 19.0, 1e-12);
    EXPECT_NEAR(s.centroid_y, (0 + 1 + 5 + 2 + 2 + 18) / 19.0, 1e-12);
    // threshold 5: only the 5 and the 9
    s = frame_stats(f, 5, 0);
    EXPECT_NEAR(s.centroid_total, 14, 1e-12);
    EXPECT_NEAR(s.centroid_x, (5 * 1 + 9 * 3) / 14.0, 1e-12);
    EXPECT_NEAR(s.centroid_y, (5 * 1 + 9 * 2) / 14.0, 1e-12);
    const double vx = (5 * 1.0 + 9 * 9) / 14 - s.centroid_x * s.centroid_x;
    EXPECT_NEAR(s.sigma_x, std::sqrt(vx), 1e-12);
    // the two points lie on one line: correlation 1
    EXPECT_NEAR(s.sigma_xy, 1, 1e-12);
    // background of a border 1 pixel wide: every pixel but (1,1) and (2,1), corners twice
    s = frame_stats(f, 1, 1);
    // strips: left column {0,1,0}, right {0,0,9}, top row {0,1,0,0}, bottom {0,1,0,9}: 21 over 14
    EXPECT_NEAR(s.net, 19 - 21.0 / 14 * 12, 1e-12);
}
