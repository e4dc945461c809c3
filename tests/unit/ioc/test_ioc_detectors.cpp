// A multi-element energy-dispersive detector's PVs (src/detector/mca_module.cpp) on a database of their
// own, in virtual time: dxp's parameters reach the processor through their records and read back
// (MaxEnergy moves CALS), dxpMED's PresetMode / PresetReal / EraseStart acquire every element and
// the sum with a put-callback that completes when they are done, the statistics read back, and an
// acquisition started through the sum or through one element is followed by the other records.
#include "detector/mca_record.hpp"
#include "detector/mca_module.hpp"
#include "registry/registry.hpp"

#include <gtest/gtest.h>

#include <memory>
#include <numeric>

using namespace beamctl;

namespace {

struct Med {
    config::IocConfig cfg;
    std::vector<std::unique_ptr<pv::LinkDevice>> devices; // outlive the records that use them
    pv::Database db;
    double now = 100; // the virtual clock [s]
    registry::Registry signals;
    std::unique_ptr<detector::McaModule> det;

    Med() {
        detector::register_detector_records(pv::RecordTypes::global());
        cfg = config::IocConfig::parse("ioc: {name: T}\n"
                                       "detectors:\n"
                                       "  mca:\n"
                                       "    - {name: mca1, elements: 3, channels: 1024, slope: 0.02, background: 100, dead_time: 4.0e-6,\n"
                                       "       preamp_gains: [2.0, 2.0, 2.1],\n"
                                       "       lines: [{name: Fe Ka, energy: 6.404, rate: 5000, fwhm: 0.16}]}\n",
                                       "/cfg/ioc.yaml");
        db.set_clock([this] { return now; });
        module::BuildContext ctx{cfg.prefix, cfg.path, signals, db, [this] { return now; }};
        det = std::make_unique<detector::McaModule>(cfg.mca, ctx);
        db.set_link_binder([this](pv::Record& r, const pv::FieldDesc&, pv::Link& l, std::string* why) -> pv::LinkDevice* {
            const std::string a = l.s().address;
            if (r.type().name() != "mca" && !det->owns(a)) return nullptr;
            std::string reason;
            auto d = det->make_device(a, reason);
            if (!d) {
                if (why) *why = reason;
                return nullptr;
            }
            devices.push_back(std::move(d));
            return devices.back().get();
        });
        db.init_records();
        step();
    }
    pv::Address addr(const std::string& n) {
        pv::Address a;
        if (!db.resolve(n, a)) throw std::runtime_error("no PV " + n);
        return a;
    }
    double get(const std::string& n, uint32_t i = 0) {
        pv::Address a = addr(n);
        std::vector<double> v(std::max<uint32_t>(a.count, 1));
        db.get(a, pv::Prim::Double, v.data(), uint32_t(v.size()));
        return v.at(i);
    }
    std::vector<double> spectrum(const std::string& n) {
        pv::Address a = addr(n);
        std::vector<double> v(a.count);
        v.resize(db.get(a, pv::Prim::Double, v.data(), a.count));
        return v;
    }
    pv::PutStatus put(const std::string& n, double v, pv::PutCallback cb = {}) { return db.put(addr(n), pv::Prim::Double, &v, 1, std::move(cb)); }
    // what the IOC loop does every 10 ms
    void step() {
        db.scan_periodic(now);
        det->publish(now);
        db.scan_io_intr();
    }
    void run(double s) {
        for (double t = 0; t < s - 1e-9; t += 0.01) {
            now += 0.01;
            step();
        }
    }
};

} // namespace

TEST(IocDetectors, DxpParametersReachTheProcessorAndReadBack) {
    Med m;
    EXPECT_DOUBLE_EQ(m.get("T:dxp1:PeakingTime"), 2.0);
    EXPECT_DOUBLE_EQ(m.get("T:dxp1:PeakingTime_RBV"), 2.0);
    EXPECT_DOUBLE_EQ(m.get("T:dxp2:MaxEnergy_RBV"), 20.48);
    EXPECT_DOUBLE_EQ(m.get("T:dxp2:MCABinWidth_RBV"), 20.0);
    EXPECT_NEAR(m.get("T:dxp3:DynamicRange_RBV"), 25.6, 1e-9); // 1.25 x MaxEnergy by default
    ASSERT_EQ(m.put("T:dxp2:MaxEnergy", 10.24), pv::PutStatus::Ok);
    m.step();
    EXPECT_DOUBLE_EQ(m.get("T:mca2.CALS"), 0.01); // the spectrum's calibration follows
    EXPECT_DOUBLE_EQ(m.get("T:mca1.CALS"), 0.02);
    EXPECT_DOUBLE_EQ(m.get("T:dxp2:MCABinWidth_RBV"), 10.0);
    ASSERT_EQ(m.put("T:dxp1:PeakingTime", 500), pv::PutStatus::Ok); // DRVH: 100 us
    m.step();
    EXPECT_DOUBLE_EQ(m.get("T:dxp1:PeakingTime_RBV"), 100);
    EXPECT_DOUBLE_EQ(m.det->mca(0).dxp().peaking_time, 100);
    EXPECT_DOUBLE_EQ(m.det->mca(1).dxp().peaking_time, 2.0);
    // the gain of element 3 is 2.1 really: its Fe Ka is 5 % high until PreampGain says so
    ASSERT_EQ(m.put("T:dxp3:PreampGain", 2.1), pv::PutStatus::Ok);
    m.step();
    EXPECT_DOUBLE_EQ(m.get("T:dxp3:PreampGain_RBV"), 2.1);
    const auto& s = m.det->mca(2).shape();
    EXPECT_EQ(std::max_element(s.begin(), s.end()) - s.begin(), 320); // 6.404 keV / 0.02
    // a held parameter reads back what was put
    ASSERT_EQ(m.put("T:dxp1:MaxWidth", 2.5), pv::PutStatus::Ok);
    m.step();
    EXPECT_DOUBLE_EQ(m.get("T:dxp1:MaxWidth_RBV"), 2.5);
}

TEST(IocDetectors, EraseStartAcquiresEveryElementAndTheSumWithPresetReal) {
    Med m;
    ASSERT_EQ(m.put("T:PresetMode", 1), pv::PutStatus::Ok); // Real time
    ASSERT_EQ(m.put("T:PresetReal", 2.0), pv::PutStatus::Ok);
    for (const char* r : {"T:mca1", "T:mca2", "T:mca3", "T:mcaSum"}) {
        EXPECT_DOUBLE_EQ(m.get(std::string(r) + ".PRTM"), 2.0) << r;
        EXPECT_DOUBLE_EQ(m.get(std::string(r) + ".PLTM"), 0) << r;
    }
    int done = 0;
    ASSERT_EQ(m.put("T:EraseStart", 1, [&](pv::PutStatus s) { done += s == pv::PutStatus::Ok ? 1 : 100; }), pv::PutStatus::Ok);
    EXPECT_EQ(done, 0);
    EXPECT_EQ(m.get("T:AcquireBusy"), 1);
    m.run(0.5);
    EXPECT_EQ(m.get("T:Acquiring"), 1);
    for (const char* r : {"T:mca1", "T:mca2", "T:mca3", "T:mcaSum"}) EXPECT_EQ(m.get(std::string(r) + ".ACQG"), 1) << r;
    m.run(2.0);
    EXPECT_EQ(done, 1);
    EXPECT_EQ(m.get("T:AcquireBusy"), 0);
    EXPECT_EQ(m.get("T:Acquiring"), 0);
    EXPECT_DOUBLE_EQ(m.get("T:ElapsedReal"), 2.0);
    EXPECT_NEAR(m.get("T:ElapsedLive"), 2.0 / (1 + 5100 * 4e-6), 1e-6);
    EXPECT_NEAR(m.get("T:DeadTime"), 100 * (1 - 1 / (1 + 5100 * 4e-6)), 1e-3);
    // every element's spectrum, the sum channel by channel
    std::vector<double> sum(1024, 0);
    for (const char* r : {"T:mca1", "T:mca2", "T:mca3"}) {
        EXPECT_DOUBLE_EQ(m.get(std::string(r) + ".ERTM"), 2.0) << r;
        const auto v = m.spectrum(r);
        ASSERT_EQ(v.size(), 1024u) << r;
        EXPECT_NEAR(std::accumulate(v.begin(), v.end(), 0.0), 5100 * m.get(std::string(r) + ".ELTM"), 500) << r;
        for (std::size_t i = 0; i < v.size(); ++i) sum[i] += v[i];
    }
    EXPECT_EQ(m.spectrum("T:mcaSum"), sum);
    // the processor's statistics
    EXPECT_DOUBLE_EQ(m.get("T:dxp1:ElapsedRealTime"), 2.0);
    const auto v1 = m.spectrum("T:mca1");
    EXPECT_EQ(m.get("T:dxp1:Events"), std::accumulate(v1.begin(), v1.end(), 0.0));
    EXPECT_NEAR(m.get("T:dxp1:InputCountRate"), 5100, 200);
    EXPECT_NEAR(m.get("T:dxp1:OutputCountRate"), m.get("T:dxp1:Events") / 2.0, 1e-6);
    // StopAll ends a long one; PresetMode "No preset" clears the real-time preset
    ASSERT_EQ(m.put("T:PresetMode", 0), pv::PutStatus::Ok);
    EXPECT_DOUBLE_EQ(m.get("T:mca2.PRTM"), 0);
    ASSERT_EQ(m.put("T:StartAll", 1), pv::PutStatus::Ok);
    m.run(5);
    EXPECT_EQ(m.get("T:Acquiring"), 1);
    ASSERT_EQ(m.put("T:StopAll", 1), pv::PutStatus::Ok);
    m.run(0.3);
    EXPECT_EQ(m.get("T:Acquiring"), 0);
    EXPECT_EQ(m.get("T:AcquireBusy"), 0);
    EXPECT_NEAR(m.get("T:mca3.ERTM"), 7.0, 0.05); // 2 s, then 5 more
}

TEST(IocDetectors, AnEventsPresetThroughTheMedPvs) {
    Med m;
    ASSERT_EQ(m.put("T:PresetEvents", 20000), pv::PutStatus::Ok);
    ASSERT_EQ(m.put("T:PresetMode", 3), pv::PutStatus::Ok); // Events
    EXPECT_EQ(m.get("T:dxp2:PresetMode"), 3);
    m.step();
    EXPECT_EQ(m.get("T:dxp2:PresetEvents_RBV"), 20000);
    EXPECT_EQ(m.get("T:dxp2:PresetMode_RBV"), 3);
    ASSERT_EQ(m.put("T:EraseStart", 1), pv::PutStatus::Ok);
    m.run(6);
    EXPECT_EQ(m.get("T:Acquiring"), 0);
    // 5100 events per live second (the whole spectrum is binned): 20000 at 3.92 s live
    for (const char* r : {"T:mca1", "T:mca2"}) EXPECT_NEAR(m.get(std::string(r) + ".ELTM"), 20000.0 / 5100, 1e-6) << r;
}

TEST(IocDetectors, TheOtherRecordsFollowAnAcquisitionStartedThroughTheSumOrOneElement) {
    Med m;
    ASSERT_EQ(m.put("T:mcaSum.PRTM", 1.0), pv::PutStatus::Ok); // the sum's presets go to every element's detector
    ASSERT_EQ(m.put("T:mcaSum.ERST", 1), pv::PutStatus::Ok);
    m.run(0.3);
    EXPECT_EQ(m.get("T:mca2.ACQG"), 1);
    EXPECT_EQ(m.get("T:Acquiring"), 1);
    m.run(1.0);
    EXPECT_EQ(m.get("T:mca2.ACQG"), 0);
    EXPECT_DOUBLE_EQ(m.get("T:mca2.ERTM"), 1.0);
    const auto v = m.spectrum("T:mca2");
    EXPECT_GT(std::accumulate(v.begin(), v.end(), 0.0), 4000); // read at the end
    // one element alone: the sum shows it acquiring
    ASSERT_EQ(m.put("T:mca1.PRTM", 0.5), pv::PutStatus::Ok);
    ASSERT_EQ(m.put("T:mca1.ERST", 1), pv::PutStatus::Ok);
    m.run(0.2);
    EXPECT_EQ(m.get("T:mcaSum.ACQG"), 1);
    m.run(0.5);
    EXPECT_EQ(m.get("T:mcaSum.ACQG"), 0);
}

TEST(IocDetectors, AnUnknownDxpParameterIsAClearError) {
    Med m;
    std::string why;
    EXPECT_TRUE(m.det->owns("mca2.Bogus"));
    EXPECT_EQ(m.det->make_device("mca2.Bogus", why), nullptr);
    EXPECT_NE(why.find("no DXP parameter 'Bogus'"), std::string::npos) << why;
    EXPECT_FALSE(m.det->owns("mca9.PeakingTime"));
    EXPECT_EQ(m.det->make_device("mca9", why), nullptr);
    EXPECT_NE(why.find("mca1, mca2, mca3, mcaSum"), std::string::npos) << why;
}
