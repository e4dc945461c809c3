// The array record types of EPICS base 7: aai, aao, subArray, compress and histogram, with "Soft
// Channel" device support. Semantics follow base's record support (aaiRecord.c, aaoRecord.c,
// subArrayRecord.c, compressRecord.c, histogramRecord.c and devAaiSoft.c, devAaoSoft.c,
// devSASoft.c, devHistogramSoft.c): arrays are read and written whole through links, NORD is the
// number of valid elements, monitors are posted as base posts them. The code is ours.
// Threading: the database thread, as every record.
#include "pv/record_support.hpp"

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstring>
#include <vector>

namespace beamctl::pv {
namespace {
using namespace support;

bool linked(const Link& l) { return l.kind == Link::Kind::Db || l.kind == Link::Kind::Hw; }

constexpr uint32_t kMaxElements = 64u * 1024 * 1024;

// An element count a .db file set (NELM, MALM, NSAM): 1..64 Mi, else a clear error.
void check_count(const char* field, uint32_t n) {
    if (n == 0) throw Error(SB() << field << " is 0; it must be at least 1");
    if (n > kMaxElements) throw Error(SB() << field << " " << n << " is too large (at most " << kMaxElements << ")");
}

// epicsMemHash's role (aai/aao HASH, for On Change posting): FNV-1a over the valid elements.
uint32_t mem_hash(const char* p, std::size_t n) {
    uint32_t h = 2166136261u;
    for (std::size_t i = 0; i < n; ++i) h = (h ^ uint8_t(p[i])) * 16777619u;
    return h;
}

// get_precision of the array records: PREC for VAL, PREC (0..15) for other float fields, else 0.
int16_t prec_of(const FieldDesc& f, const FieldDesc* val_fd, int16_t prec) {
    if (&f == val_fd) return prec;
    if (f.dbf == Dbf::Float || f.dbf == Dbf::Double) return (prec < 0 || prec > 15) ? 15 : prec;
    return 0;
}

const Menu kMenuAaiPost{"aaiPOST", {"Always", "On Change"}};

// ---------------------------------------------------------------- aai, aao and subArray storage
// VAL is NELM (subArray: MALM) elements of FTVL; NORD of them are valid.
template <typename Self> struct ArrayBase : Record {
    using Record::Record;
    uint16_t ftvl = 0; // STRING: menuFtype choice 0, base's default (no initial())
    uint32_t nelm = 1, nord = 0;
    int16_t prec = 0;
    char egu[16] = {};
    double hopr = 0, lopr = 0;
    std::vector<char> buf;
    uint16_t esize = 8;
    Dbf etype = Dbf::Double;
    char val_placeholder = 0;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* nord_fd = type().find("NORD");

    static std::vector<FieldDesc> array_fields(std::vector<FieldDesc> v, uint16_t val_flags) {
        using R = Self;
        auto add = {
            BEAMCTL_FIELD(R, VAL, val_placeholder, Double, val_flags | kArray | kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, PREC, prec, Short, kMeta),
            BEAMCTL_FIELD(R, EGU, egu, String, kMeta),
            BEAMCTL_FIELD(R, HOPR, hopr, Double, kMeta | kEgu),
            BEAMCTL_FIELD(R, LOPR, lopr, Double, kMeta | kEgu),
            BEAMCTL_MENU(R, FTVL, ftvl, kMenuFtype, kInitOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void allocate(const char* count_field, uint32_t n) {
        if (!ftvl_type(ftvl, etype, esize))
            throw Error(SB() << "FTVL " << (ftvl < kMenuFtype.choices.size() ? kMenuFtype.choices[ftvl] : "?")
                             << " is not supported for " << type().name()
                             << " (STRING, CHAR, UCHAR, SHORT, USHORT, LONG, ULONG, INT64, FLOAT, DOUBLE are)");
        check_count(count_field, n);
        buf.assign(std::size_t(n) * esize, 0);
    }
    uint32_t capacity() const { return uint32_t(buf.size() / esize); }
    Elements elements(const FieldDesc& f) override {
        if (&f != val_fd) return Record::elements(f);
        return Elements{etype, buf.data(), std::min(nord, capacity()), capacity(), esize};
    }
    void set_count(const FieldDesc& f, uint32_t n) override { // put_array_info
        if (&f != val_fd) return;
        uint32_t before = nord;
        nord = std::min(n, capacity());
        if (nord != before) post(nord_fd, kDbeValue | kDbeLog);
    }
    int16_t precision(const FieldDesc& f) const override { return prec_of(f, val_fd, prec); }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        Record::metadata(f, md);
        if (&f == val_fd) md.precision = (etype == Dbf::Float || etype == Dbf::Double) ? prec : 0;
        if (f.flags & kEgu) md.units = egu;
        if (f.flags & kDisplayHopr) fill_limits(md, hopr, lopr, hopr, lopr);
    }
};

// aai and aao: MPST/APST Always or On Change (a hash of the valid elements, HASH).
template <typename Self> struct AaBase : ArrayBase<Self> {
    using ArrayBase<Self>::ArrayBase;
    uint16_t mpst = 0, apst = 0;
    uint32_t hash = 0;
    Simulation sim;
    const FieldDesc* simm_fd = this->type().find("SIMM");
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }
    PutStatus special(const FieldDesc& f) override {
        sim_special(*this, sim, f, simm_fd);
        return PutStatus::Ok;
    }
    static std::vector<FieldDesc> aa_fields(std::vector<FieldDesc> v) {
        using R = Self;
        auto add = {
            BEAMCTL_FIELD(R, NELM, nelm, ULong, kInitOnly),
            BEAMCTL_FIELD(R, NORD, nord, ULong, kReadOnly),
            BEAMCTL_MENU(R, MPST, mpst, kMenuAaiPost, 0),
            BEAMCTL_MENU(R, APST, apst, kMenuAaiPost, 0),
            BEAMCTL_FIELD(R, HASH, hash, ULong, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void aa_monitor() {
        unsigned m = this->reset_alarms();
        if (mpst == 0) m |= kDbeValue;
        if (apst == 0) m |= kDbeLog;
        if (mpst == 1 || apst == 1) {
            uint32_t h = mem_hash(this->buf.data(), std::size_t(this->nord) * this->esize);
            if (h != hash) {
                if (mpst == 1) m |= kDbeValue;
                if (apst == 1) m |= kDbeLog;
                hash = h;
                this->post("HASH", kDbeValue);
            }
        }
        if (m) this->post(this->val_fd, m);
    }
};

struct AaiRecord : AaBase<AaiRecord> {
    using AaBase::AaBase;
    Link inp;
    static std::vector<FieldDesc> fields() {
        using R = AaiRecord;
        auto v = aa_fields(array_fields(common_fields(), kVal));
        v.push_back(BEAMCTL_FIELD(R, INP, inp, InLink, 0));
        add_simulation_fields<R>(v, false, false);
        return v;
    }
    void init() override {
        allocate("NELM", nelm);
        nord = nelm == 1;
        sim_init(*this, sim, *simm_fd);
        if (load_constant(inp, *val_fd)) udf = 0; // devAaiSoft: a constant array at init
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        Link& from = step == SimStep::Now ? sim.siol : inp; // simulated: SIOL instead of INP
        if (linked(from)) read_link(from, *val_fd); // NORD = elements read (set_count)
        udf = 0;
        stamp_time();
        aa_monitor();
        pact = 0;
        return ProcessResult::Done;
    }
};

struct AaoRecord : AaBase<AaoRecord> {
    using AaBase::AaBase;
    Link dol, out;
    uint16_t omsl = 0;
    static std::vector<FieldDesc> fields() {
        using R = AaoRecord;
        auto v = aa_fields(array_fields(common_fields(), kVal));
        auto add = {
            BEAMCTL_FIELD(R, DOL, dol, InLink, 0),
            BEAMCTL_MENU(R, OMSL, omsl, kMenuOmsl, 0),
            BEAMCTL_FIELD(R, OUT, out, OutLink, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_simulation_fields<R>(v, false, true);
        return v;
    }
    void init() override {
        allocate("NELM", nelm);
        nord = nelm == 1;
        if (out.kind == Link::Kind::Empty || out.kind == Link::Kind::Constant) nord = 0; // devAaoSoft init_record
        sim_init(*this, sim, *simm_fd);
        if (omsl == 1 && load_constant(dol, *val_fd)) udf = 0; // fetchValue(init): constant DOL
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        udf = 0;
        // fetchValue: closed_loop reads DOL; a failed read ends processing (no write, no monitor).
        if (!sim.resuming && omsl == 1 && linked(dol) && !read_link(dol, *val_fd)) {
            pact = 0;
            return ProcessResult::Done;
        }
        stamp_time();
        write_link(step == SimStep::Now ? sim.siol : out, *val_fd); // devAaoSoft: NORD elements (simulated: SIOL)
        aa_monitor();
        pact = 0;
        return ProcessResult::Done;
    }
};

// ---------------------------------------------------------------- subArray
// VAL holds the NELM elements of INP's array from index INDX on (MALM: the elements read).
struct SubArrayRecord : ArrayBase<SubArrayRecord> {
    using ArrayBase::ArrayBase;
    uint32_t malm = 1, indx = 0;
    int16_t busy = 0;
    int32_t nord_field = 0; // NORD is a LONG in subArray
    uint32_t request = 0;   // elements a link read may fill (INDX + NELM, at most MALM)
    Link inp;
    static std::vector<FieldDesc> fields() {
        using R = SubArrayRecord;
        auto v = array_fields(common_fields(), kVal);
        auto add = {
            BEAMCTL_FIELD(R, MALM, malm, ULong, kInitOnly),
            BEAMCTL_FIELD(R, NELM, nelm, ULong, kProcess),
            BEAMCTL_FIELD(R, INDX, indx, ULong, kProcess),
            BEAMCTL_FIELD(R, BUSY, busy, Short, kReadOnly),
            BEAMCTL_FIELD(R, NORD, nord_field, Long, kReadOnly),
            BEAMCTL_FIELD(R, INP, inp, InLink, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    Elements elements(const FieldDesc& f) override {
        Elements e = ArrayBase::elements(f);
        if (&f == val_fd && request) e.capacity = request; // while INP is read
        return e;
    }
    void set_count(const FieldDesc& f, uint32_t n) override {
        if (&f != val_fd) return;
        nord = std::min(n, capacity());
        nord_field = int32_t(nord);
    }
    // devSASoft's subset: elements [INDX, got) moved to the front, at most NELM of them.
    void subset(uint32_t got) {
        uint32_t count = got > indx ? std::min(got - indx, nelm) : 0;
        if (count) std::memmove(buf.data(), buf.data() + std::size_t(indx) * esize, std::size_t(count) * esize);
        nord = count;
        nord_field = int32_t(count);
    }
    uint32_t read_request() const { return std::min(indx + nelm, malm); }
    void init() override {
        allocate("MALM", malm);
        nelm = std::min(nelm, malm);
        nord = 0;
        request = read_request();
        if (load_constant(inp, *val_fd)) { // dbLoadLinkArray then subset
            subset(nord);
            udf = 0;
        }
        request = 0;
    }
    ProcessResult process() override {
        pact = 1;
        nelm = std::min(nelm, malm);
        if (indx >= malm) indx = malm - 1;
        uint32_t before = nord;
        bool ok = true;
        if (linked(inp)) {
            request = read_request();
            nord = 0;
            ok = read_link(inp, *val_fd);
            request = 0;
            if (ok) subset(nord);
            else nord = before, nord_field = int32_t(before);
        } else if (inp.is_constant()) {
            request = read_request();
            if (load_constant(inp, *val_fd)) subset(nord);
            request = 0;
        }
        if (nord != before) post(nord_fd, kDbeValue | kDbeLog);
        stamp_time();
        bool bad = !ok || nord == 0; // readValue: no elements is an error
        udf = bad;
        if (bad) set_sevr(kStatUdf, udfs);
        unsigned m = reset_alarms() | kDbeValue | kDbeLog;
        post(val_fd, m);
        pact = 0;
        return ProcessResult::Done;
    }
};

// ---------------------------------------------------------------- compress
// VAL is NSAM doubles filled from INP by ALG. Stored in order (FIFO: oldest first; LIFO: newest
// first) so that it reads as base's get_array_info presents its circular buffer; OFF counts as
// base's does.
const Menu kMenuCompressAlg{"compressALG",
                            {"N to 1 Low Value", "N to 1 High Value", "N to 1 Average", "Average",
                             "Circular Buffer", "N to 1 Median"}};
const Menu kMenuBufferingAlg{"bufferingALG", {"FIFO Buffer", "LIFO Buffer"}};
enum { kLow, kHigh, kNAverage, kAverage, kCircular, kMedian };

struct CompressRecord : Record {
    using Record::Record;
    Link inp;
    int16_t res = 0;
    uint16_t alg = 0, pbuf = 0, balg = 0;
    uint32_t nsam = 1, n = 1;
    double ihil = 0, ilil = 0, hopr = 0, lopr = 0;
    int16_t prec = 0;
    char egu[16] = {};
    uint32_t off = 0, nuse = 0, ouse = 0, inx = 0;
    int32_t inpn = 0;
    double cvb = 0;
    char val_placeholder = 0;
    std::vector<double> buf, sum, work; // VAL; the Average sums; the array read from INP
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* nuse_fd = type().find("NUSE");
    // The scratch field INP is read into (WPTR): as many elements as the target holds.
    // a function-local static: the class is complete in a function body (clang requires it)
    static const FieldDesc& work_desc() {
        static const FieldDesc d{"WPTR", Dbf::Double, kArray, 8, nullptr,
                                        [](Record& r) -> void* { return &static_cast<CompressRecord&>(r).work; }};
        return d;
    }
    uint32_t work_count = 0;

    static std::vector<FieldDesc> fields() {
        using R = CompressRecord;
        auto v = common_fields();
        auto add = {
            BEAMCTL_FIELD(R, VAL, val_placeholder, Double, kVal | kArray | kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, INP, inp, InLink, 0),
            BEAMCTL_FIELD(R, RES, res, Short, 0),
            BEAMCTL_MENU(R, ALG, alg, kMenuCompressAlg, 0),
            BEAMCTL_MENU(R, PBUF, pbuf, kMenuYesNo, 0),
            BEAMCTL_MENU(R, BALG, balg, kMenuBufferingAlg, 0),
            BEAMCTL_FIELD(R, NSAM, nsam, ULong, kInitOnly),
            BEAMCTL_FIELD(R, N, n, ULong, 0),
            BEAMCTL_FIELD(R, IHIL, ihil, Double, kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, ILIL, ilil, Double, kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, HOPR, hopr, Double, kMeta | kEgu),
            BEAMCTL_FIELD(R, LOPR, lopr, Double, kMeta | kEgu),
            BEAMCTL_FIELD(R, PREC, prec, Short, kMeta),
            BEAMCTL_FIELD(R, EGU, egu, String, kMeta),
            BEAMCTL_FIELD(R, OFF, off, ULong, kReadOnly),
            BEAMCTL_FIELD(R, NUSE, nuse, ULong, kReadOnly),
            BEAMCTL_FIELD(R, OUSE, ouse, ULong, kReadOnly),
            BEAMCTL_FIELD(R, INPN, inpn, Long, kReadOnly),
            BEAMCTL_FIELD(R, CVB, cvb, Double, kReadOnly),
            BEAMCTL_FIELD(R, INX, inx, ULong, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void reset() {
        nuse = off = inx = 0;
        cvb = 0;
        res = 0;
        std::fill(buf.begin(), buf.end(), 0.0);
    }
    void init() override {
        check_count("NSAM", nsam);
        buf.assign(nsam, 0.0);
        reset();
    }
    Elements elements(const FieldDesc& f) override {
        if (&f == &work_desc()) return Elements{Dbf::Double, work.data(), work_count, uint32_t(work.size()), 8};
        if (&f == val_fd) return Elements{Dbf::Double, buf.data(), nuse, nsam, 8};
        return Record::elements(f);
    }
    void set_count(const FieldDesc& f, uint32_t c) override {
        if (&f == &work_desc()) work_count = c;
        if (&f != val_fd) return;
        // A client's put replaces the buffer (base writes it at OFF and advances OFF instead).
        uint32_t before = nuse;
        nuse = std::min(c, nsam);
        off = balg == 0 ? nuse % nsam : 0;
        if (nuse != before) post(nuse_fd, kDbeValue | kDbeLog);
    }
    PutStatus special(const FieldDesc& f) override {
        if (is(f, "RES") || is(f, "ALG") || is(f, "BALG") || is(f, "N") || is(f, "PBUF")) reset(); // SPC_RESET
        return PutStatus::Ok;
    }
    int16_t precision(const FieldDesc& f) const override { return prec_of(f, val_fd, prec); }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        Record::metadata(f, md);
        if (&f == val_fd) md.precision = prec;
        if (f.flags & kEgu) md.units = egu;
        if (f.flags & kDisplayHopr) fill_limits(md, hopr, lopr, hopr, lopr);
    }
    // put_value: `count` values in, the oldest ones beyond NSAM dropped.
    void put_values(const double* src, uint32_t count) {
        uint32_t m = std::min(count, nsam);
        if (balg == 0) { // FIFO: oldest first
            uint32_t keep = std::min(nuse, nsam - m);
            std::memmove(buf.data(), buf.data() + (nuse - keep), std::size_t(keep) * 8);
            std::memcpy(buf.data() + keep, src + (count - m), std::size_t(m) * 8);
            off = uint32_t((uint64_t(off) + count) % nsam);
        } else { // LIFO: newest first
            uint32_t keep = std::min(nuse, nsam - m);
            std::memmove(buf.data() + m, buf.data(), std::size_t(keep) * 8);
            for (uint32_t i = 0; i < m; ++i) buf[i] = src[count - 1 - i];
            off = uint32_t((uint64_t(off) + nsam - count % nsam) % nsam);
        }
        nuse = std::min(nuse + count, nsam);
    }
    // compress_array: an array input compressed N to 1 as base 7.0.8 does it: fewer than N
    // elements (after the out-of-limit ones at its start) write nothing unless PBUF; otherwise the
    // whole array becomes one sample (base sets n to the element count); returns 1 when nothing
    // was written.
    int compress_array(double* src, int32_t count) {
        if (ilil < ihil)
            while (count > 0 && (*src < ilil || *src > ihil)) --count, ++src;
        if (n == 0) n = 1;
        if ((count < int64_t(n) && pbuf != 1) || count <= 0) return 1;
        double value = *src;
        switch (alg) {
        case kLow: value = *std::min_element(src, src + count); break;
        case kHigh: value = *std::max_element(src, src + count); break;
        case kNAverage: {
            double s = 0;
            for (int32_t j = 0; j < count; ++j) s += src[j];
            value = s / count;
            break;
        }
        case kMedian:
            std::sort(src, src + count);
            value = src[count / 2];
            break;
        }
        put_values(&value, 1);
        return 0;
    }
    // array_average: element-wise mean of N arrays.
    int array_average(const double* src, uint32_t count) {
        uint32_t use = std::min(nsam, count);
        if (sum.size() != nsam) sum.assign(nsam, 0.0);
        if (inx == 0) {
            std::copy(src, src + use, sum.begin());
        } else {
            for (uint32_t i = 0; i < use; ++i) sum[i] += src[i];
        }
        if (n == 0) n = 1;
        if (++inx < n) return 1;
        if (n > 1)
            for (uint32_t i = 0; i < use; ++i) sum[i] *= 1.0 / n;
        put_values(sum.data(), use);
        inx = 0;
        return 0;
    }
    // compress_scalar: N to 1 over successive scalar values (Median: the average).
    int compress_scalar(double value) {
        switch (alg) {
        case kLow: if (value < cvb || inx == 0) cvb = value; break;
        case kHigh: if (value > cvb || inx == 0) cvb = value; break;
        case kNAverage:
        case kMedian: cvb = (inx * cvb + value) / (inx + 1); break;
        }
        ++inx;
        if (inx >= n || pbuf == 1) {
            put_values(&cvb, 1);
            if (inx >= n) inx = 0;
            return 0;
        }
        return 1;
    }
    ProcessResult process() override {
        pact = 1;
        int status = 0;
        uint32_t avail = 0; // dbGetNelements: what INP's target holds
        RemoteLink::Value rv;
        if (inp.kind == Link::Kind::Hw && inp.device()) avail = 1;
        else if (inp.is_db() && inp.target())
            avail = (inp.target_field()->flags & kArray) ? inp.target()->elements(*inp.target_field()).capacity : 1;
        else if (RemoteLink* rl = inp.remote(); rl && rl->value(rv)) avail = std::max<uint32_t>(rv.count, 1);
        if (avail == 0) {
            set_sevr(kStatLink, kInvalid);
        } else {
            if (work.empty() || int32_t(avail) != inpn) {
                if (!work.empty()) reset();
                work.assign(avail, 0.0);
                inpn = int32_t(avail);
            }
            work_count = 0;
            if (!read_link(inp, work_desc()) || work_count == 0) {
                set_sevr(kStatLink, kInvalid);
            } else if (alg == kAverage) {
                status = array_average(work.data(), work_count);
            } else if (alg == kCircular) {
                put_values(work.data(), work_count);
            } else if (work_count > 1) {
                status = compress_array(work.data(), int32_t(work_count));
            } else {
                status = compress_scalar(work[0]);
            }
        }
        if (status != 1) { // a value was written (or an alarm raised): post
            udf = 0;
            stamp_time();
            unsigned alarm = reset_alarms();
            unsigned m = alarm | kDbeLog | kDbeValue;
            if (alarm || nuse != ouse) {
                post(nuse_fd, m);
                ouse = nuse;
            }
            post(val_fd, m);
        }
        pact = 0;
        return ProcessResult::Done;
    }
};

// ---------------------------------------------------------------- histogram
// VAL counts SGNL (read from SVL, or SIOL in simulation) in NELM bins of WDTH from LLIM to ULIM.
// Simulation mode as base 7's histogramRecord readValue: SIML gives SIMM (menuYesNo), which swaps
// SCAN and SSCN; in simulation SIOL reads SVAL into SGNL (after SDLY when SDLY >= 0) with SIMS.
const Menu kMenuHistogramCmd{"histogramCMD", {"Read", "Clear", "Start", "Stop"}};

struct HistogramRecord : Record {
    using Record::Record;
    uint16_t nelm = 1;
    int16_t csta = 1;
    uint16_t cmd = 0;
    double ulim = 0, llim = 0, wdth = 0, sgnl = 0, sdel = 0, sval = 0;
    int16_t prec = 0, mdel = 0, mcnt = 0;
    uint32_t hopr = 0, lopr = 0;
    Link svl;
    Simulation sim;
    char val_placeholder = 0;
    std::vector<uint32_t> counts;
    int wdog_pending = 0; // SDEL watchdog requests in flight (only the newest acts)
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* simm_fd = type().find("SIMM");

    static std::vector<FieldDesc> fields() {
        using R = HistogramRecord;
        auto v = common_fields();
        auto add = {
            BEAMCTL_FIELD(R, VAL, val_placeholder, ULong, kReadOnly | kAsl0 | kArray | kDisplayHopr),
            BEAMCTL_FIELD(R, NELM, nelm, UShort, kInitOnly),
            BEAMCTL_FIELD(R, CSTA, csta, Short, kReadOnly),
            BEAMCTL_MENU(R, CMD, cmd, kMenuHistogramCmd, 0),
            BEAMCTL_FIELD(R, ULIM, ulim, Double, 0),
            BEAMCTL_FIELD(R, LLIM, llim, Double, 0),
            BEAMCTL_FIELD(R, WDTH, wdth, Double, kReadOnly),
            BEAMCTL_FIELD(R, SGNL, sgnl, Double, 0),
            BEAMCTL_FIELD(R, PREC, prec, Short, kMeta),
            BEAMCTL_FIELD(R, SVL, svl, InLink, 0),
            BEAMCTL_FIELD(R, MDEL, mdel, Short, 0),
            BEAMCTL_FIELD(R, MCNT, mcnt, Short, kReadOnly),
            BEAMCTL_FIELD(R, SDEL, sdel, Double, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        // The simulation fields in histogramRecord.dbd's order (SVAL between SIOL and SIML).
        std::vector<FieldDesc> sim_fields;
        add_simulation_fields<R>(sim_fields, false, false);
        auto take = [&](std::string_view name) {
            for (const FieldDesc& f : sim_fields)
                if (name == f.name) v.push_back(f);
        };
        take("SIOL");
        v.push_back(BEAMCTL_FIELD(R, SVAL, sval, Double, 0));
        for (auto name : {"SIML", "SIMM", "SIMS", "OLDSIMM", "SSCN", "SDLY"}) take(name);
        auto display = {BEAMCTL_FIELD(R, HOPR, hopr, ULong, kMeta), BEAMCTL_FIELD(R, LOPR, lopr, ULong, kMeta)};
        v.insert(v.end(), display.begin(), display.end());
        return v;
    }
    void init() override {
        check_count("NELM", nelm);
        counts.assign(nelm, 0);
        wdth = (ulim - llim) / nelm;
        sim_init(*this, sim, *simm_fd);
        load_constant(sim.siol, sval);
        if (load_constant(svl, sgnl)) udf = 0;
        wdog_start();
    }
    void wdog_start() {
        if (sdel <= 0) return;
        ++wdog_pending;
        call_after(sdel);
    }
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) {
            sim_resume(*this, sim);
            return;
        }
        // wdogCallback: post counts that changed, then again after SDEL
        if (--wdog_pending > 0) return;
        if (mcnt > 0) {
            stamp_time();
            post(val_fd, kDbeValue | kDbeLog);
            mcnt = 0;
        }
        wdog_start();
    }
    void clear() {
        std::fill(counts.begin(), counts.end(), 0u);
        mcnt = int16_t(mdel + 1);
        udf = 0;
    }
    void add_count() {
        if (!csta) return;
        if (llim >= ulim) return; // base raises SOFT/INVALID here, which its monitor resets at once
        if (sgnl < llim || sgnl >= ulim) return;
        double t = sgnl - llim;
        int i = 1;
        for (; i <= nelm; ++i)
            if (t <= double(i) * wdth) break;
        uint32_t& c = counts[std::min(i, int(nelm)) - 1];
        if (c == UINT_MAX) c = 0;
        ++c;
        ++mcnt;
    }
    PutStatus special(const FieldDesc& f) override {
        sim_special(*this, sim, f, simm_fd);
        if (is(f, "CMD")) { // SPC_CALC: Read/Clear clear, Start/Stop set CSTA
            if (cmd <= 1) clear();
            else csta = cmd == 2;
            cmd = 0;
        } else if (is(f, "SGNL")) {
            add_count();
        } else if (is(f, "SDEL")) {
            wdog_start();
        } else if (is(f, "ULIM") || is(f, "LLIM")) {
            wdth = (ulim - llim) / nelm;
            clear();
            post("WDTH", kDbeValue | kDbeLog);
        }
        return PutStatus::Ok;
    }
    Elements elements(const FieldDesc& f) override {
        if (&f == val_fd) return Elements{Dbf::ULong, counts.data(), nelm, nelm, 4};
        return Record::elements(f);
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        Record::metadata(f, md);
        if (&f == val_fd) fill_limits(md, hopr, lopr, hopr, lopr);
    }
    int16_t precision(const FieldDesc& f) const override { // histogramRecord's get_precision
        if (is(f, "SDEL")) return 2; // histogramSDELprecision
        if (is(f, "ULIM") || is(f, "LLIM") || is(f, "SGNL") || is(f, "SVAL") || is(f, "WDTH")) return prec;
        return Record::precision(f);
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        bool count = true;
        if (step == SimStep::Now) {
            count = read_link(sim.siol, sval); // a failed SIOL read adds no count (status != 0)
            if (count) {
                sgnl = sval;
                udf = 0;
            }
        } else if (linked(svl)) {
            read_link(svl, sgnl); // devHistogramSoft ignores the status: counts SGNL as it is
        }
        stamp_time();
        if (count) add_count();
        unsigned m = reset_alarms();
        if (mcnt > mdel) {
            m |= kDbeValue | kDbeLog;
            mcnt = 0;
        }
        if (m) post(val_fd, m);
        pact = 0;
        return ProcessResult::Done;
    }
};

} // namespace

void register_array_records(RecordTypes& types) {
    add_type<AaiRecord>(types, "aai");
    add_type<AaoRecord>(types, "aao");
    add_type<SubArrayRecord>(types, "subArray");
    add_type<CompressRecord>(types, "compress");
    add_type<HistogramRecord>(types, "histogram");
}

} // namespace beamctl::pv
