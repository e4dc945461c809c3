// The area detector's PVs on a database of their own, the exposures in virtual time (the clock and
// the beam are the test's): a put-callback on Acquire completes only once every plugin has the
// frames, Multiple/Continuous/Software triggers take the frames they should, the statistics see
// the beam where it is, Stream capture writes the file, and refused puts change nothing.
#include "ioc/area_detector.hpp"

#include "../temp_dir.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <chrono>
#include <cstring>
#include <thread>

using namespace beamctl;

namespace {

struct Camera {
    config::IocConfig cfg;
    pv::Database db;
    double now = 100;      // the virtual clock [s]
    ethercat::sim::BeamTally beam; // what the plant publishes (the test moves it)
    std::unique_ptr<ioc::IocAreaDetector> ad;

    explicit Camera(const std::string& extra = "") {
        cfg = config::IocConfig::parse("ioc: {name: T}\n"
                                       "detectors:\n"
                                       "  area_detector:\n"
                                       "    - {size: [100, 80], pixel_size: 0.01, photons_per_flux: 1.0e+9, acquire_time: 0.01,\n"
                                       "       acquire_period: 0.05" + extra + "}\n",
                                       "/cfg/ioc.yaml");
        beam.sigma_x = 0.05, beam.sigma_y = 0.03, beam.flux = 1;
        beam.left = beam.bottom = -1e300, beam.right = beam.top = 1e300;
        ad = std::make_unique<ioc::IocAreaDetector>(cfg, db, [this] { return now; });
        ad->bind([this](int) -> ioc::IocAreaDetector::BeamSource { return [this] { return beam; }; });
        db.init_records();
        ad->start();
        spot_at(0, 0);
    }
    // The spot resting at (x, y) mm from now on: the tally's sums advance with the clock.
    void spot_at(double x, double y) { sx = x, sy = y; }
    // Advances the virtual clock by `s` in 5 ms steps (the beam's tally with it), polling the
    // detector, and lets the worker finish what it has.
    void run(double s) {
        for (double t = 0; t < s - 1e-9; t += 0.005) {
            now += 0.005;
            beam.t = now, beam.w += 0.005, beam.sx += sx * 0.005, beam.sy += sy * 0.005;
            beam.sxx += sx * sx * 0.005, beam.syy += sy * sy * 0.005, beam.st += 0.005;
            beam.x = sx, beam.y = sy, beam.transmission = 1;
            settle();
            ad->poll(now);
        }
        settle();
        ad->poll(now);
    }
    void settle() { // the worker's work is done (not a timing: it waits for completion)
        for (int i = 0; i < 20000 && ad->busy_worker(); ++i) std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
    pv::Address addr(const std::string& n) {
        pv::Address a;
        EXPECT_TRUE(db.resolve(n, a)) << n;
        return a;
    }
    pv::PutStatus put(const std::string& n, double v, pv::PutCallback cb = {}) {
        return db.put(addr(n), pv::Prim::Double, &v, 1, std::move(cb));
    }
    pv::PutStatus put_text(const std::string& n, const std::string& s) {
        std::vector<char> c(s.begin(), s.end());
        c.push_back(0);
        return db.put(addr(n), pv::Prim::Char, c.data(), uint32_t(c.size()));
    }
    double get(const std::string& n) {
        double d = 0;
        db.get(addr(n), pv::Prim::Double, &d, 1);
        return d;
    }
    std::string text(const std::string& n) {
        char s[256] = {};
        db.get(addr(n), pv::Prim::Char, s, 255);
        return s;
    }
    double sx = 0, sy = 0;
};

} // namespace

TEST(IocAreaDetector, APutCallbackOnAcquireCompletesWhenThePluginsHaveTheFrame) {
    Camera c;
    EXPECT_EQ(c.get("T:cam1:MaxSizeX_RBV"), 100);
    EXPECT_EQ(c.get("T:cam1:DetectorState_RBV"), 0);
    c.put("T:Stats1:CentroidThreshold", 50);
    c.spot_at(0.1, -0.05); // 10 columns right, 5 rows down of the centre
    int done = 0;
    ASSERT_EQ(c.put("T:cam1:Acquire", 1, [&](pv::PutStatus s) { done += s == pv::PutStatus::Ok ? 1 : 100; }), pv::PutStatus::Ok);
    EXPECT_EQ(c.get("T:cam1:AcquireBusy"), 1);
    EXPECT_EQ(c.get("T:cam1:Acquire_RBV"), 1);
    EXPECT_EQ(done, 0);
    c.now += 0.005;
    c.ad->poll(c.now); // half the exposure: nothing yet
    EXPECT_EQ(done, 0);
    EXPECT_EQ(c.get("T:cam1:DetectorState_RBV"), 1);
    c.run(0.02);
    EXPECT_EQ(done, 1);
    EXPECT_EQ(c.get("T:cam1:Acquire"), 0);
    EXPECT_EQ(c.get("T:cam1:AcquireBusy"), 0);
    EXPECT_EQ(c.get("T:cam1:ArrayCounter_RBV"), 1);
    EXPECT_EQ(c.get("T:Stats1:ArrayCounter_RBV"), 1);
    EXPECT_EQ(c.get("T:image1:ArraySize0_RBV"), 100);
    EXPECT_NEAR(c.get("T:Stats1:CentroidX_RBV"), 49.5 + 10, 0.2);
    EXPECT_NEAR(c.get("T:Stats1:CentroidY_RBV"), 39.5 + 5, 0.2);
    EXPECT_NEAR(c.get("T:Stats1:SigmaX_RBV"), 5, 0.2);
}

TEST(IocAreaDetector, MultipleContinuousAndSoftwareTriggers) {
    Camera c;
    c.put("T:cam1:ImageMode", 1);
    c.put("T:cam1:NumImages", 4);
    int done = 0;
    c.put("T:cam1:Acquire", 1, [&](pv::PutStatus) { ++done; });
    c.run(0.1); // 0.05 s a frame: 2 or 3 so far
    EXPECT_EQ(done, 0);
    EXPECT_GE(c.get("T:cam1:NumImagesCounter_RBV"), 2);
    EXPECT_EQ(c.get("T:cam1:DetectorState_RBV") == 7 || c.get("T:cam1:DetectorState_RBV") == 1, true);
    c.run(0.2);
    EXPECT_EQ(done, 1);
    EXPECT_EQ(c.get("T:cam1:NumImagesCounter_RBV"), 4);
    EXPECT_EQ(c.get("T:cam1:ArrayCounter_RBV"), 4);
    // Continuous until Acquire 0: 20 frames in a second
    c.put("T:cam1:ImageMode", 2);
    c.put("T:cam1:Acquire", 1);
    c.run(1.0);
    c.put("T:cam1:Acquire", 0);
    c.run(0.01);
    const double n = c.get("T:cam1:ArrayCounter_RBV") - 4;
    EXPECT_GE(n, 19);
    EXPECT_LE(n, 21);
    EXPECT_EQ(c.get("T:cam1:DetectorState_RBV"), 0);
    // Software: a frame a TriggerSoftware, refused when not acquiring
    EXPECT_EQ(c.put("T:cam1:TriggerSoftware", 1), pv::PutStatus::Failed);
    c.put("T:cam1:TriggerMode", 1);
    c.put("T:cam1:Acquire", 1);
    c.run(0.5);
    EXPECT_EQ(c.get("T:cam1:DetectorState_RBV"), 7); // waiting for a trigger
    const double before = c.get("T:cam1:ArrayCounter_RBV");
    EXPECT_EQ(c.put("T:cam1:TriggerSoftware", 1), pv::PutStatus::Ok);
    c.run(0.5);
    EXPECT_EQ(c.get("T:cam1:ArrayCounter_RBV"), before + 1);
    // a period shorter than the polls: still one frame a trigger
    c.put("T:cam1:Acquire", 0);
    c.run(0.01);
    c.put("T:cam1:AcquirePeriod", 0);
    c.put("T:cam1:Acquire", 1);
    c.run(0.1);
    EXPECT_EQ(c.put("T:cam1:TriggerSoftware", 1), pv::PutStatus::Ok);
    EXPECT_EQ(c.put("T:cam1:TriggerSoftware", 1), pv::PutStatus::Ok);
    c.run(0.5);
    EXPECT_EQ(c.get("T:cam1:ArrayCounter_RBV"), before + 3);
    EXPECT_EQ(c.get("T:cam1:DetectorState_RBV"), 7);
    c.put("T:cam1:Acquire", 0);
    c.run(0.01);
    EXPECT_EQ(c.get("T:cam1:DetectorState_RBV"), 0);
}

TEST(IocAreaDetector, StreamCaptureWritesTheFrames) {
    test::TempDir dir;
    Camera c;
    ASSERT_EQ(c.put_text("T:HDF1:FilePath", dir.path.string()), pv::PutStatus::Ok);
    EXPECT_EQ(c.text("T:HDF1:FilePath_RBV"), dir.path.string() + "/");
    EXPECT_EQ(c.get("T:HDF1:FilePathExists_RBV"), 1);
    c.put("T:HDF1:FileWriteMode", 2);
    c.put("T:HDF1:NumCapture", 3);
    int captured = 0;
    ASSERT_EQ(c.put("T:HDF1:Capture", 1, [&](pv::PutStatus) { ++captured; }), pv::PutStatus::Ok);
    c.run(0.01);
    EXPECT_EQ(c.text("T:HDF1:FullFileName_RBV"), dir.path.string() + "/cam1_001.h5");
    EXPECT_EQ(c.get("T:HDF1:FileNumber"), 2);
    c.put("T:cam1:ImageMode", 1);
    c.put("T:cam1:NumImages", 5);
    c.put("T:cam1:Acquire", 1);
    c.run(0.4);
    EXPECT_EQ(captured, 1); // the capture ended with its third frame
    EXPECT_EQ(c.get("T:HDF1:NumCaptured_RBV"), 3);
    EXPECT_EQ(c.get("T:HDF1:Capture_RBV"), 0);
    EXPECT_EQ(c.get("T:HDF1:WriteStatus"), 0);
    hid_t f = H5Fopen((dir.path / "cam1_001.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    hid_t d = H5Dopen2(f, "/entry/data/data", H5P_DEFAULT);
    hsize_t dims[3] = {};
    H5Sget_simple_extent_dims(H5Dget_space(d), dims, nullptr);
    EXPECT_EQ(dims[0], 3u);
    EXPECT_EQ(dims[1], 80u);
    EXPECT_EQ(dims[2], 100u);
    H5Dclose(d);
    H5Fclose(f);
}

TEST(IocAreaDetector, RefusedPutsChangeNothing) {
    Camera c;
    EXPECT_EQ(c.put("T:cam1:AcquireTime", -1), pv::PutStatus::Failed);
    EXPECT_EQ(c.get("T:cam1:AcquireTime_RBV"), 0.01);
    EXPECT_EQ(c.put("T:cam1:DataType", 7), pv::PutStatus::Failed); // UInt64
    EXPECT_EQ(c.get("T:cam1:DataType"), 3);
    EXPECT_EQ(c.put("T:cam1:ColorMode", 2), pv::PutStatus::Failed);
    EXPECT_EQ(c.put_text("T:HDF1:FileTemplate", "%s%s%n"), pv::PutStatus::Failed);
    EXPECT_EQ(c.text("T:HDF1:FileTemplate"), "%s%s_%3.3d.h5");
    EXPECT_EQ(c.put("T:HDF1:Capture", 1), pv::PutStatus::Failed); // FileWriteMode Single
    EXPECT_EQ(c.put("T:HDF1:ReadFile", 1), pv::PutStatus::Failed);
    // a region past the sensor: clipped, as the readbacks show
    EXPECT_EQ(c.put("T:cam1:MinX", 90), pv::PutStatus::Ok);
    EXPECT_EQ(c.get("T:cam1:SizeX_RBV"), 10);
    EXPECT_EQ(c.get("T:cam1:ArraySizeX_RBV"), 10);
}
