// The mca record (see mca_record.hpp). Semantics follow mca's mcaRecord.c (process, special,
// sum_ROIs, mcaAlarm, monitor) with a synchronous device (no read-status or read-data callbacks);
// the code is ours.
#include "detector/mca_record.hpp"

#include "pv/database.hpp"
#include "pv/record_support.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <string>
#include <utility>
#include <vector>

namespace beamctl::detector {
namespace {
using namespace pv;
using namespace pv::support;

const Menu kMenuMcaStrt{"mcaSTRT", {"Done", "Acquire"}};
const Menu kMenuMcaRead{"mcaREAD", {"Done", "Read"}};
const Menu kMenuMcaEras{"mcaERAS", {"Done", "Erase"}};
const Menu kMenuMcaMode{"mcaMODE", {"PHA", "MCS", "List"}};
const Menu kMenuMcaChas{"mcaCHAS", {"Internal", "External"}};
const Menu kMenuMcaIp{"mcaR0IP", {"N", "Y"}};
const Menu kMenuMcaDtyp{"DTYP", {"Soft Channel", "asynMCA"}};

constexpr int kRois = 32;
constexpr uint32_t kMaxChannels = 1u << 20;

struct Roi {
    int32_t lo = -1, hi = -1;
    int16_t bg = 0;
    uint16_t ip = 0;
    double sum = 0, net = 0, preset = 0;
    char nm[16] = {};
};

// The ROI fields' names: R<n>LO HI BG IP (32 each, in that order), then R<n> N P, then R<n>NM.
enum RoiField { kLo, kHi, kBg, kIp, kSum, kNet, kPreset, kName, kRoiFields };
const std::vector<std::string>& roi_names() {
    static const std::vector<std::string> names = [] {
        std::vector<std::string> v(kRois * kRoiFields);
        static const char* const suffix[kRoiFields] = {"LO", "HI", "BG", "IP", "", "N", "P", "NM"};
        for (int k = 0; k < kRoiFields; ++k)
            for (int i = 0; i < kRois; ++i) v[std::size_t(k * kRois + i)] = "R" + std::to_string(i) + suffix[k];
        return v;
    }();
    return names;
}

struct McaRecord : Record {
    using Record::Record;
    double vers = 1;
    char val_placeholder = 0, bg_placeholder = 0;
    double hopr = 0, lopr = 0;
    int32_t nmax = 1, nord = 0;
    int16_t prec = 0;
    uint16_t ftvl = 5; // LONG
    uint16_t strt = 0, erst = 0, stop = 0, acqg = 0, read = 0, rdng = 0, rdns = 0, eras = 0, chas = 0;
    int32_t nuse = 0, seq = 0, pscl = 1;
    double dwel = 1, prtm = 0, pltm = 0, pct = 0;
    int32_t pctl = 0, pcth = 0, pswp = 1;
    uint16_t mode = 0;
    double calo = 0, cals = 1, calq = 0;
    char egu[16] = {};
    double tth = 10, ertm = 0, eltm = 0, dtim = 0, idtim = 0;
    char stim[40] = {};
    double rtim = 0;
    int32_t act = 0;
    int16_t nack = 0;
    Link inp;
    double hihi = 0, lolo = 0, high = 0, low = 0;
    uint16_t hhsv = 0, llsv = 0, hsv = 0, lsv = 0;
    double hyst = 0, lalm = 0;
    uint32_t newv = 0; // set-up fields put since the last processing (bits below)
    uint32_t newr = 0; // ROIs to sum again
    Roi roi[kRois];

    std::vector<int32_t> data, bg;
    McaDevice* device = nullptr;
    bool device_set = false; // given by set_mca_device (not through INP)
    bool acquire_waiting = false; // returned Async: a put-callback / FLNK waits for the end
    uint32_t mmap = 0, rmap = 0;  // fields / ROI sums to post

    enum : uint32_t {
        M_VAL = 1u << 0, M_NACK = 1u << 1, M_BG = 1u << 2, M_ACQG = 1u << 3, M_READ = 1u << 4, M_ERTM = 1u << 5,
        M_ELTM = 1u << 6, M_ACT = 1u << 7, M_STRT = 1u << 8, M_STOP = 1u << 9, M_STIM = 1u << 10, M_RTIM = 1u << 11,
        M_DTIM = 1u << 12, M_IDTIM = 1u << 13, M_NORD = 1u << 14, M_ERAS = 1u << 15, M_ERST = 1u << 16, M_DWEL = 1u << 17,
        M_NUSE = 1u << 18,
    };
    // newv bits: which set-up fields changed
    enum : uint32_t { N_SETUP = 1u << 0, N_ERAS = 1u << 1, N_ERST = 1u << 2 };

    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* bg_fd = type().find("BG");
    FieldRun roi_fd; // R0LO .. R31NM in kRoiFields runs of kRois

    template <int K, std::size_t... I> static void add_roi(std::vector<FieldDesc>& v, Dbf t, uint16_t flags, const Menu* menu,
                                                          std::index_sequence<I...>) {
        (v.push_back(FieldDesc{roi_names()[K * kRois + I].c_str(), t, flags, roi_size<K>(), menu,
                               [](Record& r) -> void* { return roi_addr<K>(static_cast<McaRecord&>(r).roi[I]); }}),
         ...);
    }
    template <int K> static uint16_t roi_size() {
        Roi x;
        return K == kName ? uint16_t(sizeof x.nm) : K == kLo || K == kHi ? 4 : K == kBg || K == kIp ? 2 : 8;
    }
    template <int K> static void* roi_addr(Roi& x) {
        if constexpr (K == kLo) return &x.lo;
        else if constexpr (K == kHi) return &x.hi;
        else if constexpr (K == kBg) return &x.bg;
        else if constexpr (K == kIp) return &x.ip;
        else if constexpr (K == kSum) return &x.sum;
        else if constexpr (K == kNet) return &x.net;
        else if constexpr (K == kPreset) return &x.preset;
        else return &x.nm;
    }

    static std::vector<FieldDesc> fields() {
        using R = McaRecord;
        auto v = common_fields();
        for (auto& f : v)
            if (std::strcmp(f.name, "DTYP") == 0) f.menu = &kMenuMcaDtyp;
        constexpr uint16_t kRo = kReadOnly, kPp = kProcess;
        auto add = {
            BEAMCTL_FIELD(R, VERS, vers, Double, kRo),
            BEAMCTL_FIELD(R, VAL, val_placeholder, Long, kVal | kArray),
            BEAMCTL_FIELD(R, BG, bg_placeholder, Long, kProcess | kArray),
            BEAMCTL_FIELD(R, HOPR, hopr, Double, kMeta),
            BEAMCTL_FIELD(R, LOPR, lopr, Double, kMeta),
            BEAMCTL_FIELD(R, NMAX, nmax, Long, kInitOnly),
            BEAMCTL_FIELD(R, NORD, nord, Long, kRo),
            BEAMCTL_FIELD(R, PREC, prec, Short, kMeta),
            BEAMCTL_MENU(R, FTVL, ftvl, kMenuFtype, kInitOnly),
            BEAMCTL_MENU(R, STRT, strt, kMenuMcaStrt, kPp),
            BEAMCTL_MENU(R, ERST, erst, kMenuMcaStrt, kPp),
            BEAMCTL_MENU(R, STOP, stop, kMenuMcaStrt, kPp),
            BEAMCTL_MENU(R, ACQG, acqg, kMenuMcaStrt, kRo),
            BEAMCTL_MENU(R, READ, read, kMenuMcaRead, kPp),
            BEAMCTL_MENU(R, RDNG, rdng, kMenuMcaRead, kRo),
            BEAMCTL_MENU(R, RDNS, rdns, kMenuMcaRead, kRo),
            BEAMCTL_MENU(R, ERAS, eras, kMenuMcaEras, kPp),
            BEAMCTL_MENU(R, CHAS, chas, kMenuMcaChas, kPp),
            BEAMCTL_FIELD(R, NUSE, nuse, Long, kPp),
            BEAMCTL_FIELD(R, SEQ, seq, Long, kPp),
            BEAMCTL_FIELD(R, DWEL, dwel, Double, kPp),
            BEAMCTL_FIELD(R, PSCL, pscl, Long, kPp),
            BEAMCTL_FIELD(R, PRTM, prtm, Double, kPp),
            BEAMCTL_FIELD(R, PLTM, pltm, Double, kPp),
            BEAMCTL_FIELD(R, PCT, pct, Double, kPp),
            BEAMCTL_FIELD(R, PCTL, pctl, Long, kPp),
            BEAMCTL_FIELD(R, PCTH, pcth, Long, kPp),
            BEAMCTL_FIELD(R, PSWP, pswp, Long, kPp),
            BEAMCTL_MENU(R, MODE, mode, kMenuMcaMode, kPp),
            BEAMCTL_FIELD(R, CALO, calo, Double, 0),
            BEAMCTL_FIELD(R, CALS, cals, Double, 0),
            BEAMCTL_FIELD(R, CALQ, calq, Double, 0),
            BEAMCTL_FIELD(R, EGU, egu, String, kMeta),
            BEAMCTL_FIELD(R, TTH, tth, Double, 0),
            BEAMCTL_FIELD(R, ERTM, ertm, Double, 0),
            BEAMCTL_FIELD(R, ELTM, eltm, Double, 0),
            BEAMCTL_FIELD(R, DTIM, dtim, Double, kRo),
            BEAMCTL_FIELD(R, IDTIM, idtim, Double, kRo),
            BEAMCTL_FIELD(R, STIM, stim, String, kRo),
            BEAMCTL_FIELD(R, RTIM, rtim, Double, kRo),
            BEAMCTL_FIELD(R, ACT, act, Long, kRo),
            BEAMCTL_FIELD(R, NACK, nack, Short, kRo),
            BEAMCTL_FIELD(R, INP, inp, InLink, 0),
            BEAMCTL_FIELD(R, HIHI, hihi, Double, kMeta),
            BEAMCTL_FIELD(R, LOLO, lolo, Double, kMeta),
            BEAMCTL_FIELD(R, HIGH, high, Double, kMeta),
            BEAMCTL_FIELD(R, LOW, low, Double, kMeta),
            BEAMCTL_MENU(R, HHSV, hhsv, kMenuAlarmSevr, 0),
            BEAMCTL_MENU(R, LLSV, llsv, kMenuAlarmSevr, 0),
            BEAMCTL_MENU(R, HSV, hsv, kMenuAlarmSevr, 0),
            BEAMCTL_MENU(R, LSV, lsv, kMenuAlarmSevr, 0),
            BEAMCTL_FIELD(R, HYST, hyst, Double, 0),
            BEAMCTL_FIELD(R, LALM, lalm, Double, kRo),
            BEAMCTL_FIELD(R, NEWV, newv, ULong, kRo),
            BEAMCTL_FIELD(R, NEWR, newr, ULong, kRo),
        };
        v.insert(v.end(), add.begin(), add.end());
        constexpr auto seq = std::make_index_sequence<kRois>{};
        add_roi<kLo>(v, Dbf::Long, kPp, nullptr, seq);
        add_roi<kHi>(v, Dbf::Long, kPp, nullptr, seq);
        add_roi<kBg>(v, Dbf::Short, kPp, nullptr, seq);
        add_roi<kIp>(v, Dbf::Menu, kPp, &kMenuMcaIp, seq);
        add_roi<kSum>(v, Dbf::Double, kRo, nullptr, seq);
        add_roi<kNet>(v, Dbf::Double, kRo, nullptr, seq);
        add_roi<kPreset>(v, Dbf::Double, 0, nullptr, seq);
        add_roi<kName>(v, Dbf::String, 0, nullptr, seq);
        return v;
    }
    // ROI field f: its ROI and kind, or false.
    bool roi_of(const FieldDesc& f, int& i, int& k) const {
        const int n = roi_fd.index_of(f, kRois * kRoiFields);
        if (n < 0) return false;
        k = n / kRois;
        i = n % kRois;
        return true;
    }

    void init() override {
        static const char* first[] = {"R0LO"};
        roi_fd.first = type().find(first[0]);
        if (ftvl != 5) throw Error(SB() << "mca " << name() << ": FTVL " << kMenuFtype.choices[ftvl] << " is not supported (LONG)");
        if (nmax <= 0) nmax = 1;
        if (uint32_t(nmax) > kMaxChannels) throw Error(SB() << "mca " << name() << ": NMAX " << nmax << " is too large (at most 1048576)");
        data.assign(std::size_t(nmax), 0);
        bg.assign(std::size_t(nmax), 0);
        if (nuse <= 0 || nuse > nmax) nuse = nmax;
        if (!device_set) device = dynamic_cast<McaDevice*>(inp.device());
        newv = N_SETUP; // the device gets the set-up at the first processing
    }

    Elements elements(const FieldDesc& f) override {
        if (&f == val_fd) return Elements{Dbf::Long, data.data(), uint32_t(std::max(nord, 1)), uint32_t(data.size()), 4};
        if (&f == bg_fd) return Elements{Dbf::Long, bg.data(), uint32_t(std::max(nord, 1)), uint32_t(bg.size()), 4};
        return Record::elements(f);
    }
    void set_count(const FieldDesc& f, uint32_t n) override {
        if (&f == val_fd) nord = int32_t(std::min<uint32_t>(n, uint32_t(nmax)));
    }

    PutStatus special(const FieldDesc& f) override {
        int i, k;
        if (is(f, "MODE") && (mode >= kMenuMcaMode.choices.size() || (device && !device->supports(McaMode(mode)))))
            return PutStatus::BadValue; // the device does not acquire so: refused, MODE stays
        if (is(f, "ERAS")) newv |= N_ERAS;
        else if (is(f, "ERST")) newv |= N_ERST;
        else if (is(f, "NUSE")) {
            newv |= N_SETUP;
            read = 1; // a new number of channels: read the spectrum again
            mmap |= M_READ;
        } else if (is(f, "CHAS") || is(f, "SEQ") || is(f, "DWEL") || is(f, "PSCL") || is(f, "PRTM") || is(f, "PLTM") || is(f, "PCT") ||
                   is(f, "PCTL") || is(f, "PCTH") || is(f, "PSWP") || is(f, "MODE"))
            newv |= N_SETUP;
        else if (roi_of(f, i, k) && k <= kIp)
            newr |= 1u << i;
        return PutStatus::Ok;
    }

    ProcessResult process() override {
        pact = 1;
        if (nack) {
            nack = 0;
            mmap |= M_NACK;
        }
        McaDevice* dev = device;
        auto refused = [&](bool ok) {
            if (!ok) {
                nack = 1;
                mmap |= M_NACK;
            }
        };
        if (!dev) set_sevr(kStatSoft, kInvalid);
        const bool was_acquiring = acqg != 0;
        if (dev && (newv & N_SETUP)) {
            if (nuse > nmax) nuse = nmax;
            McaDevice::Setup s;
            s.nuse = nuse, s.prtm = prtm, s.pltm = pltm, s.pct = pct, s.pctl = pctl, s.pcth = pcth, s.pswp = pswp, s.dwel = dwel;
            s.mode = McaMode(mode);
            refused(dev->setup(s));
            mmap |= M_NUSE;
        }
        if (newv & (N_ERAS | N_ERST)) {
            if (dev) refused(dev->erase());
            nord = 0;
            mmap |= M_NORD;
            std::fill(data.begin(), data.begin() + std::min<std::size_t>(std::size_t(nuse), data.size()), 0);
            if (newv & N_ERAS) { // ERAS posts the zeroed spectrum; ERST lets the new data come
                eras = 0;
                mmap |= M_ERAS | M_VAL;
                newr = ~0u;
            }
        }
        if (dev && (strt || (newv & N_ERST))) {
            refused(dev->start());
            acqg = 1; // forced, so that an acquisition over before the first status read is read
            mmap |= M_ACQG;
            if (strt) strt = 0, mmap |= M_STRT;
            if (newv & N_ERST) erst = 0, mmap |= M_ERST;
        }
        newv = 0;
        if (stop) {
            if (dev) refused(dev->stop());
            stop = 0;
            mmap |= M_STOP;
        }
        // status
        McaDevice::Status st;
        if (dev && dev->status(st)) {
            const double ertp = ertm, eltp = eltm;
            if (ertm != st.real) ertm = st.real, mmap |= M_ERTM;
            if (eltm != st.live) eltm = st.live, mmap |= M_ELTM;
            if (act != st.total) act = st.total, mmap |= M_ACT;
            if (dwel != st.dwell) dwel = st.dwell, mmap |= M_DWEL;
            if (mmap & (M_ERTM | M_ELTM)) {
                dtim = ertm > .001 ? std::clamp(100. * (ertm - eltm) / ertm, 0., 100.) : 0.;
                if (acqg) {
                    const double drt = ertm - ertp;
                    idtim = drt > .001 ? std::clamp(100. * (drt - (eltm - eltp)) / drt, 0., 100.) : 0.;
                } else {
                    idtim = dtim;
                }
                mmap |= M_DTIM | M_IDTIM;
            }
            if (acqg && !st.acquiring) read = 1, mmap |= M_READ; // acquisition ended: read the data first
        } else {
            if (dev) refused(false);
            st.acquiring = false;
        }
        if (read) {
            rtim = database() ? database()->now() : 0;
            mmap |= M_RTIM;
            if (dev) {
                const int32_t before = nord;
                nord = int32_t(dev->read(data.data(), uint32_t(std::min(nuse, nmax))));
                if (nord != before) mmap |= M_NORD;
                mmap |= M_VAL;
                newr = ~0u;
            }
            read = 0;
            mmap |= M_READ;
        }
        if (newr) {
            if (sum_rois() && dev) refused(dev->stop()); // an ROI preset reached
        }
        if (acqg != (st.acquiring ? 1 : 0)) {
            acqg = st.acquiring ? 1 : 0;
            mmap |= M_ACQG;
        }
        udf = 0;
        stamp_time();
        if (!acqg) {
            const std::time_t t = std::time(nullptr);
            std::tm tm{};
            localtime_r(&t, &tm);
            std::strftime(stim, sizeof stim, "%b %d, %Y %H:%M:%S", &tm);
            mmap |= M_STIM;
        }
        alarms();
        monitor();
        pact = 0;
        if (acqg) { // the forward link and a waiting put-callback: when the acquisition ends
            acquire_waiting = true;
            return ProcessResult::Async;
        }
        if (acquire_waiting || was_acquiring) {
            acquire_waiting = false;
            async_done(); // completes a put-callback waiting since the start; FLNK follows (Done)
        }
        return ProcessResult::Done;
    }

    // mcaRecord.c sum_ROIs: totals, nets over a straight background, the BG array; true when an
    // ROI with IP = Y reached its preset.
    bool sum_rois() {
        bool preset_reached = false;
        const int32_t max = nord - 1;
        std::fill(bg.begin(), bg.end(), 0);
        int32_t ymax = 0;
        for (int32_t i = 0; i < max; ++i) ymax = std::max(ymax, data[std::size_t(i)]);
        for (int r = 0; r < kRois; ++r) {
            Roi& x = roi[r];
            double sum = 0, net = 0;
            const int32_t lo = x.lo;
            const int32_t hi = std::min(x.hi, max);
            if (lo >= 0 && hi >= lo) {
                double bg_lo = 0, bg_hi = 0;
                if (x.bg >= 0) {
                    const int32_t n = x.bg;
                    for (int32_t i = std::max(lo - n, 0); i <= std::min(lo + n, max); ++i) bg_lo += data[std::size_t(i)];
                    bg_lo /= 2 * n + 1;
                    for (int32_t i = std::max(hi - n, 0); i <= std::min(hi + n, max); ++i) bg_hi += data[std::size_t(i)];
                    bg_hi /= 2 * n + 1;
                }
                const int32_t n = hi - lo;
                for (int32_t j = 0; j <= n; ++j) {
                    const int32_t p = data[std::size_t(lo + j)];
                    int32_t& b = bg[std::size_t(lo + j)];
                    sum += p;
                    if (x.bg >= 0) b = int32_t(bg_lo + (n ? j * (bg_hi - bg_lo) / n : 0)); // LONG, as FTVL
                    net += p - b;
                }
                mmap |= M_BG;
            }
            if (sum != x.sum || net != x.net) rmap |= 1u << r;
            x.sum = sum;
            x.net = net;
            if (x.ip && x.net >= x.preset) preset_reached = true;
        }
        for (int r = 0; r < kRois; ++r) { // the ends of each ROI marked at the spectrum's maximum
            const int32_t lo = roi[r].lo, hi = std::min(roi[r].hi, max);
            if (lo >= 0 && hi >= lo) bg[std::size_t(lo)] = bg[std::size_t(hi)] = ymax;
        }
        newr = 0;
        return preset_reached;
    }

    // mcaAlarm: limit alarms on IDTIM (the dead time, %).
    void alarms() {
        if (udf) {
            set_sevr(kStatUdf, kInvalid);
            return;
        }
        limit_alarms<double>(*this, idtim, hihi, high, low, lolo, hhsv, hsv, lsv, llsv, hyst, lalm);
    }

    void monitor() {
        const unsigned mask = reset_alarms() | kDbeValue | kDbeLog;
        auto post_if = [&](uint32_t bit, const char* field) {
            if (mmap & bit) post(field, mask);
        };
        post_if(M_VAL, "VAL");
        post_if(M_BG, "BG");
        post_if(M_NACK, "NACK");
        post_if(M_READ, "READ");
        post_if(M_ERTM, "ERTM");
        post_if(M_ELTM, "ELTM");
        post_if(M_ACT, "ACT");
        post_if(M_STRT, "STRT");
        post_if(M_STOP, "STOP");
        post_if(M_ERAS, "ERAS");
        post_if(M_ERST, "ERST");
        post_if(M_STIM, "STIM");
        post_if(M_RTIM, "RTIM");
        post_if(M_DWEL, "DWEL");
        post_if(M_DTIM, "DTIM");
        post_if(M_IDTIM, "IDTIM");
        post_if(M_NORD, "NORD");
        post_if(M_NUSE, "NUSE");
        for (int r = 0; r < kRois; ++r)
            if (rmap & (1u << r)) {
                post(roi_fd[kSum * kRois + r], mask);
                post(roi_fd[kNet * kRois + r], mask);
            }
        post_if(M_ACQG, "ACQG"); // last: the data and ROIs are there before ACQG falls
        mmap = 0;
        rmap = 0;
    }

    int16_t precision(const FieldDesc& f) const override {
        if (is(f, "CALO") || is(f, "CALS") || is(f, "CALQ") || is(f, "TTH")) return 6;
        if (f.dbf == Dbf::Float || f.dbf == Dbf::Double) return (prec < 0 || prec > 15) ? 15 : prec;
        return 0;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        Record::metadata(f, md);
        md.units = egu;
        if (is(f, "DTIM") || is(f, "IDTIM")) {
            md.disp_hi = 100;
            md.disp_lo = 0;
        }
        if (&f == val_fd) fill_limits(md, hopr, lopr, hopr, lopr);
    }
};

} // namespace

void register_detector_records(RecordTypes& types) {
    if (!types.find("mca")) add_type<McaRecord>(types, "mca");
}

bool set_mca_device(Record& r, McaDevice* device) {
    auto* m = dynamic_cast<McaRecord*>(&r);
    if (!m) return false;
    m->device = device;
    m->device_set = true;
    return true;
}

} // namespace beamctl::detector
