// The EPICS base records that compute and sequence through links: calc, calcout, seq, fanout,
// dfanout, sel and event. Semantics follow base 7's record support (calcRecord.c,
// calcoutRecord.c, seqRecord.c, fanoutRecord.c, dfanoutRecord.c, selRecord.c, eventRecord.c):
// input links are read at the start of processing, alarms are checked before outputs are
// written, monitors are posted, then the forward link. The code is ours.
// Delays (calcout ODLY, seq DLYn) run on the database's clock (Database::call_after): the record
// stays active (PACT) meanwhile, and a put-callback completes after the delayed output.
// Threading: the database thread, as every record.
#include "pv/calc.hpp"
#include "pv/database.hpp"
#include "pv/record_support.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <utility>

namespace beamctl::pv {
namespace {
using namespace support;

constexpr int kN = calc::kArgs; // A..U
const char* const kInpNames[kN] = {"INPA", "INPB", "INPC", "INPD", "INPE", "INPF", "INPG",
                                    "INPH", "INPI", "INPJ", "INPK", "INPL", "INPM", "INPN",
                                    "INPO", "INPP", "INPQ", "INPR", "INPS", "INPT", "INPU"};
const char* const kArgNames[kN] = {"A", "B", "C", "D", "E", "F", "G", "H", "I", "J", "K",
                                    "L", "M", "N", "O", "P", "Q", "R", "S", "T", "U"};
const char* const kLastNames[kN] = {"LA", "LB", "LC", "LD", "LE", "LF", "LG", "LH", "LI", "LJ", "LK",
                                     "LL", "LM", "LN", "LO", "LP", "LQ", "LR", "LS", "LT", "LU"};

const Menu kMenuCalcoutOopt{"calcoutOOPT",
                            {"Every Time", "On Change", "When Zero", "When Non-zero",
                             "Transition To Zero", "Transition To Non-zero"}};
const Menu kMenuCalcoutDopt{"calcoutDOPT", {"Use CALC", "Use OCAL"}};
const Menu kMenuCalcoutInav{"calcoutINAV", {"Ext PV NC", "Ext PV OK", "Local PV", "Constant"}};
const Menu kMenuSelm{"seqSELM", {"All", "Specified", "Mask"}};
const Menu kMenuSelSelm{"selSELM", {"Specified", "High Signal", "Low Signal", "Median Signal"}};

// A field descriptor for element I of an array member (the macros take plain members).
template <typename R, std::size_t I> void* inp_addr(Record& r) { return &static_cast<R&>(r).inp[I]; }
template <typename R, std::size_t I> void* arg_addr(Record& r) { return &static_cast<R&>(r).args[I]; }
template <typename R, std::size_t I> void* last_addr(Record& r) { return &static_cast<R&>(r).last[I]; }

// INPA..INPU, A..U (pp, shown with PREC/HOPR/LOPR) and LA..LU of a calc-like record R.
template <typename R, std::size_t... I> void add_calc_args(std::vector<FieldDesc>& v, std::index_sequence<I...>) {
    (v.push_back(FieldDesc{kInpNames[I], Dbf::InLink, 0, uint16_t(sizeof(Link)), nullptr, &inp_addr<R, I>}), ...);
    (v.push_back(FieldDesc{kArgNames[I], Dbf::Double, uint16_t(kProcess | kEgu | kDisplayHopr), 8, nullptr,
                           &arg_addr<R, I>}),
     ...);
    (v.push_back(FieldDesc{kLastNames[I], Dbf::Double, uint16_t(kReadOnly | kEgu | kDisplayHopr), 8, nullptr,
                           &last_addr<R, I>}),
     ...);
}

// The calc part shared by calc and calcout: CALC compiled once (at init and on a put), INPx
// read into A..U, the expression evaluated into VAL.
template <typename Self> struct CalcBase : AnalogBase<Self> {
    using AnalogBase<Self>::AnalogBase;
    char calc_text[calc::kMaxInfix] = "0";
    calc::Program prog;
    Link inp[kN];
    double args[kN] = {};
    double last[kN] = {};
    const FieldDesc* calc_fd = this->type().find("CALC");
    const FieldDesc* val_fd = this->type().find("VAL");
    FieldRun arg_fd; // A..U

    static std::vector<FieldDesc> calc_fields() {
        auto v = Self::analog_fields(Record::common_fields());
        for (auto& f : v)
            if (std::strcmp(f.name, "VAL") == 0) f.flags &= uint16_t(~kProcess); // VAL is the result
        v.push_back(FieldDesc{"CALC", Dbf::String, kProcess, calc::kMaxInfix, nullptr,
                              [](Record& r) -> void* { return static_cast<Self&>(r).calc_text; }});
        add_calc_args<Self>(v, std::make_index_sequence<kN>{});
        return v;
    }
    // Compiles CALC; on error says why (at init: a load error; on a put: refused).
    bool compile_calc(const char* text, calc::Program& out, std::string* why) {
        calc::CompileError err;
        if (calc::compile(std::string_view(text, strnlen(text, calc::kMaxInfix)), out, &err)) return true;
        if (why) *why = SB() << "'" << text << "': " << err.message;
        return false;
    }
    void calc_init() {
        std::string why;
        if (!compile_calc(calc_text, prog, &why)) throw Error(SB() << "CALC " << why);
        arg_fd.bind(this->type(), kArgNames, kN);
        for (int i = 0; i < kN; ++i) this->load_constant(inp[i], args[i]);
    }
    PutStatus calc_special(const FieldDesc& f) {
        if (&f != calc_fd) return PutStatus::Ok;
        calc::Program p;
        if (!compile_calc(calc_text, p, nullptr)) return PutStatus::BadValue;
        prog = std::move(p);
        return PutStatus::Ok;
    }
    // fetch_values: every input link into its argument; false if one failed (no evaluation).
    bool fetch_args() {
        bool ok = true;
        for (int i = 0; i < kN; ++i)
            if (inp[i].kind == Link::Kind::Db || inp[i].kind == Link::Kind::Hw) ok = this->read_link(inp[i], args[i]) && ok;
        return ok;
    }
    // Evaluates CALC into VAL (CALC/INVALID alarm on an evaluation error).
    void evaluate() {
        if (!fetch_args()) return;
        if (!calc::perform(prog, args, &this->val))
            this->set_sevr(kStatCalc, kInvalid);
        else
            this->udf = std::isnan(this->val);
    }
    // monitor(): VAL with its deadbands, then every argument that changed.
    void calc_monitor() {
        if (unsigned m = this->analog_monitor_mask()) this->post(val_fd, m);
        for (int i = 0; i < kN; ++i)
            if (args[i] != last[i]) {
                this->post(arg_fd[i], kDbeValue | kDbeLog);
                last[i] = args[i];
            }
    }
    void metadata(const FieldDesc& f, Metadata& md) const override { this->analog_metadata(f, md, this->hopr, this->lopr); }
};

// ---------------------------------------------------------------- calc
struct CalcRecord : CalcBase<CalcRecord> {
    using CalcBase::CalcBase;
    double aftc = 0, afvl = 0; // the alarm filter (as ai's)
    static std::vector<FieldDesc> fields() {
        using R = CalcRecord;
        auto v = calc_fields();
        v.push_back(BEAMCTL_FIELD(R, AFTC, aftc, Double, 0));
        v.push_back(BEAMCTL_FIELD(R, AFVL, afvl, Double, kReadOnly));
        return v;
    }
    void init() override { calc_init(); }
    PutStatus special(const FieldDesc& f) override { return calc_special(f); }
    ProcessResult process() override {
        pact = 1;
        EpicsTime last_time = time;
        evaluate();
        stamp_time();
        limit_alarms<double>(*this, val, hihi, high, low, lolo, hhsv, hsv, lsv, llsv, hyst, lalm, aftc, &afvl,
                             seconds_between(time, last_time));
        calc_monitor();
        pact = 0;
        return ProcessResult::Done;
    }
};

// ---------------------------------------------------------------- calcout
struct CalcoutRecord : CalcBase<CalcoutRecord> {
    using CalcBase::CalcBase;
    Link out;
    uint16_t oopt = 0, dopt = 0, ivoa = 0, dlya = 0;
    char ocal_text[calc::kMaxInfix] = "0";
    calc::Program oprog;
    double oval = 0, povl = 0, pval = 0, odly = 0, ivov = 0;
    char oevt[40] = {};
    bool delayed = false;
    const FieldDesc* oval_fd = type().find("OVAL");
    int16_t precision(const FieldDesc& f) const override {
        if (is(f, "ODLY")) return 2; // calcoutODLYprecision
        return CalcBase::precision(f);
    }
    const FieldDesc* ocal_fd = type().find("OCAL");

    static std::vector<FieldDesc> fields() {
        using R = CalcoutRecord;
        auto v = calc_fields();
        auto add = {
            BEAMCTL_FIELD(R, OUT, out, OutLink, 0),
            BEAMCTL_MENU(R, OOPT, oopt, kMenuCalcoutOopt, 0),
            BEAMCTL_MENU(R, DOPT, dopt, kMenuCalcoutDopt, 0),
            BEAMCTL_FIELD(R, OCAL, ocal_text, String, kProcess),
            BEAMCTL_FIELD(R, OVAL, oval, Double, kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, POVL, povl, Double, kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, PVAL, pval, Double, kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, ODLY, odly, Double, 0),
            BEAMCTL_FIELD(R, DLYA, dlya, UShort, kReadOnly),
            BEAMCTL_MENU(R, IVOA, ivoa, kMenuIvoa, 0),
            BEAMCTL_FIELD(R, IVOV, ivov, Double, 0),
            BEAMCTL_FIELD(R, OEVT, oevt, String, 0),
            BEAMCTL_FIELD(R, CLCV, clcv, Long, 0),
            BEAMCTL_FIELD(R, OCLV, oclv, Long, 0),
            BEAMCTL_MENU(R, OUTV, outv, kMenuCalcoutInav, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_link_status<R>(v, std::make_index_sequence<kN>{});
        return v;
    }
    // INAV..INUV: what each input link is (calcoutINAV), as base's checkLinks sets them.
    uint16_t inav[kN] = {};
    uint16_t outv = 0;
    int32_t clcv = 0, oclv = 0; // 0: CALC / OCAL compiled (base: the postfix error code)
    template <typename R, std::size_t... I> static void add_link_status(std::vector<FieldDesc>& v, std::index_sequence<I...>) {
        static const char* const names[] = {"INAV", "INBV", "INCV", "INDV", "INEV", "INFV", "INGV", "INHV", "INIV",
                                            "INJV", "INKV", "INLV", "INMV", "INNV", "INOV", "INPV", "INQV", "INRV",
                                            "INSV", "INTV", "INUV"};
        (v.push_back(FieldDesc{names[I], Dbf::Menu, kReadOnly, 2, &kMenuCalcoutInav,
                               [](Record& r) -> void* { return &static_cast<R&>(r).inav[I]; }}),
         ...);
    }
    static uint16_t link_status(const Link& l) {
        if (l.kind != Link::Kind::Db) return 3; // Constant (an empty link is one)
        if (RemoteLink* rl = l.remote()) return rl->connected() ? 1 : 0;
        return 2; // Local PV
    }
    // checkLinks: a CA link's status follows its connection (posted when it changes).
    void update_link_status() {
        static const char* const names[] = {"INAV", "INBV", "INCV", "INDV", "INEV", "INFV", "INGV", "INHV", "INIV",
                                            "INJV", "INKV", "INLV", "INMV", "INNV", "INOV", "INPV", "INQV", "INRV",
                                            "INSV", "INTV", "INUV"};
        for (int i = 0; i < kN; ++i) {
            uint16_t st = link_status(inp[i]);
            if (st == inav[i]) continue;
            inav[i] = st;
            post(names[i], kDbeValue | kDbeLog);
        }
        if (uint16_t st = link_status(out); st != outv) {
            outv = st;
            post("OUTV", kDbeValue | kDbeLog);
        }
    }
    void init() override {
        calc_init();
        std::string why;
        if (!compile_calc(ocal_text, oprog, &why)) throw Error(SB() << "OCAL " << why);
        pval = val;
        for (int i = 0; i < kN; ++i) inav[i] = link_status(inp[i]);
        outv = link_status(out);
    }
    PutStatus special(const FieldDesc& f) override {
        if (&f == ocal_fd) {
            calc::Program p;
            if (!compile_calc(ocal_text, p, nullptr)) return PutStatus::BadValue;
            oprog = std::move(p);
            return PutStatus::Ok;
        }
        return calc_special(f);
    }
    bool wants_output() const {
        switch (oopt) {
        case 0: return true;                                   // Every Time
        case 1: return std::fabs(pval - val) > mdel;           // On Change
        case 2: return val == 0;                               // When Zero
        case 3: return val != 0;                               // When Non-zero
        case 4: return pval != 0 && val == 0;                  // Transition To Zero
        case 5: return pval == 0 && val != 0;                  // Transition To Non-zero
        default: return false;
        }
    }
    // execOutput: OVAL from VAL or OCAL, written unless IVOA says otherwise, then OEVT.
    void exec_output() {
        if (dopt == 0) {
            oval = val;
        } else if (!calc::perform(oprog, args, &oval)) {
            set_sevr(kStatCalc, kInvalid);
        } else {
            udf = std::isnan(oval);
        }
        if (nsev >= kInvalid) {
            if (ivoa == 1) return;
            if (ivoa == 2) oval = ivov;
        }
        write_link(out, *oval_fd);
        if (oevt[0] && database()) database()->post_event(std::string_view(oevt, strnlen(oevt, sizeof oevt)));
    }
    void finish() {
        stamp_time();
        calc_monitor();
        if (oval != povl) {
            post(oval_fd, kDbeValue | kDbeLog);
            povl = oval;
        }
    }
    ProcessResult process() override {
        pact = 1;
        update_link_status();
        evaluate();
        analog_alarms();
        bool output = wants_output();
        pval = val;
        if (output && odly > 0) { // the output, monitors and forward link after ODLY seconds
            dlya = 1;
            post("DLYA", kDbeValue);
            delayed = true;
            call_after(odly);
            return ProcessResult::Async;
        }
        if (output) exec_output();
        finish();
        pact = 0;
        return ProcessResult::Done;
    }
    void on_delay() override {
        if (!delayed) return;
        delayed = false;
        dlya = 0;
        post("DLYA", kDbeValue);
        exec_output();
        finish();
        fwd_link(flnk);
        pact = 0;
        async_done();
    }
};

// ---------------------------------------------------------------- seq, fanout
constexpr int kGroups = 16;

// SELM/SELN/SELL/OFFS/SHFT of seq and fanout: which of their 16 groups or links run.
template <typename Self> struct Selecting : Record {
    using Record::Record;
    int32_t val = 0;
    uint16_t selm = 0, seln = 1; // SELN initial("1") (seq, fanout)
    int16_t offs = 0, shft = -1;
    Link sell;
    const FieldDesc* val_fd = type().find("VAL");

    static std::vector<FieldDesc> selection_fields() {
        using R = Self;
        auto v = common_fields();
        auto add = {
            BEAMCTL_FIELD(R, VAL, val, Long, kVal),
            BEAMCTL_MENU(R, SELM, selm, kMenuSelm, 0),
            BEAMCTL_FIELD(R, SELN, seln, UShort, 0),
            BEAMCTL_FIELD(R, SELL, sell, InLink, 0),
            BEAMCTL_FIELD(R, OFFS, offs, Short, 0),
            BEAMCTL_FIELD(R, SHFT, shft, Short, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void selection_init() {
        double v;
        if (load_constant(sell, v)) seln = uint16_t(v);
    }
    // SELN (through SELL), then the groups: All; Specified SELN+OFFS; Mask SELN shifted right by
    // SHFT (left if negative). Out of range: SOFT/INVALID and none.
    uint32_t selected() {
        udf = 0; // processed: defined (as base's seq and fanout)
        if (sell.kind == Link::Kind::Db || sell.kind == Link::Kind::Hw) {
            double v = seln;
            if (read_link(sell, v)) seln = uint16_t(v);
        }
        if (selm == 0) return (1u << kGroups) - 1;
        if (selm == 1) {
            int i = int(seln) + offs;
            if (i >= 0 && i < kGroups) return 1u << i;
        } else if (shft >= -15 && shft <= 15) {
            return (shft >= 0 ? uint32_t(seln) >> shft : uint32_t(seln) << -shft) & 0xFFFF;
        }
        set_sevr(kStatSoft, kInvalid);
        return 0;
    }
};

// Sixteen groups 0..F of (DLYn, DOLn -> DOn, LNKn); SELM chooses which run, in order.
struct SeqRecord : Selecting<SeqRecord> {
    using Selecting::Selecting;
    uint16_t oldn = 0;
    int16_t prec = 0;
    const int dly1_index = type().find("DLY1")->index; // DLY0 (the group before DLY1) has PREC
    double dly[kGroups] = {};
    Link dol[kGroups];
    double dov[kGroups] = {};
    Link lnk[kGroups];
    uint32_t pending_mask = 0; // groups still to run in this processing
    int next = 0;
    bool delayed = false;
    FieldRun do_fd; // DO0..DOF

    static std::vector<FieldDesc> fields() {
        using R = SeqRecord;
        auto v = selection_fields();
        auto add = {
            BEAMCTL_FIELD(R, OLDN, oldn, UShort, 0),
            BEAMCTL_FIELD(R, PREC, prec, Short, kMeta),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_groups(v, std::make_index_sequence<kGroups>{});
        return v;
    }
    template <std::size_t... I> static void add_groups(std::vector<FieldDesc>& v, std::index_sequence<I...>) {
        static const char* dly_n[] = {"DLY0", "DLY1", "DLY2", "DLY3", "DLY4", "DLY5", "DLY6", "DLY7",
                                      "DLY8", "DLY9", "DLYA", "DLYB", "DLYC", "DLYD", "DLYE", "DLYF"};
        static const char* dol_n[] = {"DOL0", "DOL1", "DOL2", "DOL3", "DOL4", "DOL5", "DOL6", "DOL7",
                                      "DOL8", "DOL9", "DOLA", "DOLB", "DOLC", "DOLD", "DOLE", "DOLF"};
        static const char* do_n[] = {"DO0", "DO1", "DO2", "DO3", "DO4", "DO5", "DO6", "DO7",
                                     "DO8", "DO9", "DOA", "DOB", "DOC", "DOD", "DOE", "DOF"};
        static const char* lnk_n[] = {"LNK0", "LNK1", "LNK2", "LNK3", "LNK4", "LNK5", "LNK6", "LNK7",
                                      "LNK8", "LNK9", "LNKA", "LNKB", "LNKC", "LNKD", "LNKE", "LNKF"};
        (v.push_back(FieldDesc{dly_n[I], Dbf::Double, 0, 8, nullptr,
                               [](Record& r) -> void* { return &static_cast<SeqRecord&>(r).dly[I]; }}),
         ...);
        (v.push_back(FieldDesc{dol_n[I], Dbf::InLink, 0, uint16_t(sizeof(Link)), nullptr,
                               [](Record& r) -> void* { return &static_cast<SeqRecord&>(r).dol[I]; }}),
         ...);
        (v.push_back(FieldDesc{do_n[I], Dbf::Double, 0, 8, nullptr,
                               [](Record& r) -> void* { return &static_cast<SeqRecord&>(r).dov[I]; }}),
         ...);
        (v.push_back(FieldDesc{lnk_n[I], Dbf::OutLink, 0, uint16_t(sizeof(Link)), nullptr,
                               [](Record& r) -> void* { return &static_cast<SeqRecord&>(r).lnk[I]; }}),
         ...);
    }
    void init() override {
        static const char* do_n[] = {"DO0", "DO1", "DO2", "DO3", "DO4", "DO5", "DO6", "DO7",
                                     "DO8", "DO9", "DOA", "DOB", "DOC", "DOD", "DOE", "DOF"};
        do_fd.bind(type(), do_n, kGroups);
        for (int i = 0; i < kGroups; ++i) load_constant(dol[i], dov[i]);
        selection_init();
        oldn = seln; // seqRecord init_record
    }
    int16_t precision(const FieldDesc& f) const override {
        if (f.index >= dly1_index && f.name[0] == 'D' && f.name[1] == 'L' && f.name[2] == 'Y') return 2; // DLY1..: seqDLYprecision
        if (f.dbf == Dbf::Double) return prec;
        return Record::precision(f);
    }
    // Runs groups from `next` on; returns false when a delay was scheduled.
    bool run_groups() {
        while (next < kGroups) {
            int i = next;
            if (!(pending_mask & (1u << i)) || lnk[i].empty()) {
                ++next;
                continue;
            }
            if (dly[i] > 0 && !delayed) {
                delayed = true;
                call_after(dly[i]);
                return false;
            }
            delayed = false;
            ++next;
            if (dol[i].kind == Link::Kind::Db || dol[i].kind == Link::Kind::Hw) read_link(dol[i], dov[i]);
            write_link(lnk[i], *do_fd[i]);
        }
        return true;
    }
    void finish() {
        stamp_time();
        post(val_fd, kDbeValue | kDbeLog | reset_alarms());
        if (oldn != seln) {
            oldn = seln;
            post("OLDN", kDbeValue);
        }
    }
    ProcessResult process() override {
        pact = 1;
        pending_mask = selected();
        next = 0;
        delayed = false;
        if (!run_groups()) return ProcessResult::Async;
        finish();
        pact = 0;
        return ProcessResult::Done;
    }
    void on_delay() override {
        if (!delayed) return;
        if (!run_groups()) return;
        finish();
        fwd_link(flnk);
        pact = 0;
        async_done();
    }
};

// Processes the forward links LNK0..LNKF that SELM selects.
struct FanoutRecord : Selecting<FanoutRecord> {
    using Selecting::Selecting;
    Link lnk[kGroups];

    static std::vector<FieldDesc> fields() {
        auto v = selection_fields();
        add_links(v, std::make_index_sequence<kGroups>{});
        return v;
    }
    template <std::size_t... I> static void add_links(std::vector<FieldDesc>& v, std::index_sequence<I...>) {
        static const char* n[] = {"LNK0", "LNK1", "LNK2", "LNK3", "LNK4", "LNK5", "LNK6", "LNK7",
                                  "LNK8", "LNK9", "LNKA", "LNKB", "LNKC", "LNKD", "LNKE", "LNKF"};
        (v.push_back(FieldDesc{n[I], Dbf::FwdLink, 0, uint16_t(sizeof(Link)), nullptr,
                               [](Record& r) -> void* { return &static_cast<FanoutRecord&>(r).lnk[I]; }}),
         ...);
    }
    void init() override { selection_init(); }
    ProcessResult process() override {
        pact = 1;
        uint32_t mask = selected();
        for (int i = 0; i < kGroups; ++i)
            if (mask & (1u << i)) fwd_link(lnk[i]);
        stamp_time();
        unsigned m = reset_alarms();
        post(val_fd, kDbeValue | kDbeLog | m);
        pact = 0;
        return ProcessResult::Done;
    }
};

// ---------------------------------------------------------------- dfanout
struct DfanoutRecord : AnalogBase<DfanoutRecord> {
    using AnalogBase::AnalogBase;
    uint16_t selm = 0, seln = 1, omsl = 0;
    Link sell, dol;
    Link outs[kGroups];
    const FieldDesc* val_fd = type().find("VAL");

    static std::vector<FieldDesc> fields() {
        using R = DfanoutRecord;
        auto v = analog_fields(common_fields());
        auto add = {
            BEAMCTL_MENU(R, SELM, selm, kMenuSelm, 0),
            BEAMCTL_FIELD(R, SELN, seln, UShort, 0),
            BEAMCTL_FIELD(R, SELL, sell, InLink, 0),
            BEAMCTL_FIELD(R, DOL, dol, InLink, 0),
            BEAMCTL_MENU(R, OMSL, omsl, kMenuOmsl, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_outs(v, std::make_index_sequence<kGroups>{});
        return v;
    }
    template <std::size_t... I> static void add_outs(std::vector<FieldDesc>& v, std::index_sequence<I...>) {
        static const char* n[] = {"OUTA", "OUTB", "OUTC", "OUTD", "OUTE", "OUTF", "OUTG", "OUTH",
                                  "OUTI", "OUTJ", "OUTK", "OUTL", "OUTM", "OUTN", "OUTO", "OUTP"};
        (v.push_back(FieldDesc{n[I], Dbf::OutLink, 0, uint16_t(sizeof(Link)), nullptr,
                               [](Record& r) -> void* { return &static_cast<DfanoutRecord&>(r).outs[I]; }}),
         ...);
    }
    void init() override {
        if (load_constant(dol, *val_fd)) udf = std::isnan(val);
        double v;
        if (load_constant(sell, v)) seln = uint16_t(v);
    }
    ProcessResult process() override {
        pact = 1;
        if (omsl == 1 && soft_read(*this, dol, *val_fd)) udf = std::isnan(val);
        if (sell.kind == Link::Kind::Db || sell.kind == Link::Kind::Hw) {
            double v = seln;
            if (read_link(sell, v)) seln = uint16_t(v);
        }
        analog_alarms();
        if (selm == 0) {
            for (auto& o : outs) write_link(o, *val_fd);
        } else if (selm == 1) { // Specified: SELN 1..16 names OUTA..OUTP
            if (seln == 0 || seln > kGroups) set_sevr(kStatSoft, kInvalid);
            else write_link(outs[seln - 1], *val_fd);
        } else {
            for (int i = 0; i < kGroups; ++i)
                if (seln & (1u << i)) write_link(outs[i], *val_fd);
        }
        stamp_time();
        if (unsigned m = analog_monitor_mask()) post(val_fd, m);
        pact = 0;
        return ProcessResult::Done;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override { analog_metadata(f, md, hopr, lopr); }
};

// ---------------------------------------------------------------- sel
constexpr int kSelInputs = 12; // A..L
struct SelRecord : AnalogBase<SelRecord> {
    using AnalogBase::AnalogBase;
    uint16_t selm = 0, seln = 0, nlst = 0; // NLST: the SELN last posted
    Link nvl;
    Link inp[kSelInputs];
    double args[kSelInputs];
    double last[kSelInputs];
    const FieldDesc* val_fd = type().find("VAL");
    FieldRun arg_fd; // A..L

    explicit SelRecord(const RecordType& t) : AnalogBase(t) {
        std::fill(std::begin(args), std::end(args), NAN); // unused inputs take no part
        std::fill(std::begin(last), std::end(last), 0.0); // LA..LL start 0, as base's
    }
    static std::vector<FieldDesc> fields() {
        using R = SelRecord;
        auto v = analog_fields(common_fields());
        for (auto& f : v)
            if (std::strcmp(f.name, "VAL") == 0) f.flags &= uint16_t(~kProcess);
        auto add = {
            BEAMCTL_MENU(R, SELM, selm, kMenuSelSelm, 0),
            BEAMCTL_FIELD(R, SELN, seln, UShort, kProcess),
            BEAMCTL_FIELD(R, NVL, nvl, InLink, 0),
            BEAMCTL_FIELD(R, NLST, nlst, UShort, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_inputs(v, std::make_index_sequence<kSelInputs>{});
        return v;
    }
    template <std::size_t... I> static void add_inputs(std::vector<FieldDesc>& v, std::index_sequence<I...>) {
        (v.push_back(FieldDesc{kInpNames[I], Dbf::InLink, 0, uint16_t(sizeof(Link)), nullptr, &inp_addr<SelRecord, I>}), ...);
        (v.push_back(FieldDesc{kArgNames[I], Dbf::Double, uint16_t(kProcess | kEgu | kDisplayHopr), 8, nullptr,
                               &arg_addr<SelRecord, I>}),
         ...);
        (v.push_back(FieldDesc{kLastNames[I], Dbf::Double, uint16_t(kReadOnly | kEgu | kDisplayHopr), 8, nullptr,
                               &last_addr<SelRecord, I>}),
         ...);
    }
    void init() override {
        arg_fd.bind(type(), kArgNames, kSelInputs);
        for (int i = 0; i < kSelInputs; ++i) load_constant(inp[i], args[i]);
        double v;
        if (load_constant(nvl, v)) seln = uint16_t(v);
    }
    ProcessResult process() override {
        pact = 1;
        if (nvl.kind == Link::Kind::Db || nvl.kind == Link::Kind::Hw) {
            double v = seln;
            if (read_link(nvl, v)) seln = uint16_t(v);
        }
        bool ok = true;
        if (selm == 0) {
            if (seln < kSelInputs && (inp[seln].kind == Link::Kind::Db || inp[seln].kind == Link::Kind::Hw))
                ok = read_link(inp[seln], args[seln]);
        } else {
            for (int i = 0; i < kSelInputs; ++i)
                if (inp[i].kind == Link::Kind::Db || inp[i].kind == Link::Kind::Hw) ok = read_link(inp[i], args[i]) && ok;
        }
        if (ok) select();
        stamp_time();
        analog_alarms();
        unsigned m = analog_monitor_mask();
        if (m) post(val_fd, m);
        if (nlst != seln) { // selRecord's monitor: SELN posted when it changed
            nlst = seln;
            post("SELN", m | kDbeValue | kDbeLog);
        }
        for (int i = 0; i < kSelInputs; ++i)
            if (!(args[i] == last[i]) && !(std::isnan(args[i]) && std::isnan(last[i]))) {
                post(arg_fd[i], kDbeValue | kDbeLog);
                last[i] = args[i];
            }
        pact = 0;
        return ProcessResult::Done;
    }
    // do_sel: the chosen, highest, lowest or median of the inputs that hold a number.
    void select() {
        if (selm == 0) {
            if (seln >= kSelInputs) {
                set_sevr(kStatSoft, kInvalid);
                return;
            }
            val = args[seln];
        } else {
            double v[kSelInputs];
            int n = 0;
            for (double a : args)
                if (!std::isnan(a)) v[n++] = a;
            if (n == 0) {
                val = NAN;
            } else if (selm == 1) {
                val = *std::max_element(v, v + n);
            } else if (selm == 2) {
                val = *std::min_element(v, v + n);
            } else {
                std::sort(v, v + n);
                val = v[n / 2];
            }
        }
        udf = std::isnan(val);
    }
    void metadata(const FieldDesc& f, Metadata& md) const override { analog_metadata(f, md, hopr, lopr); }
};

// ---------------------------------------------------------------- event
// eventRecord: VAL names the event its processing posts; INP reads VAL, or in simulation mode
// (SIMM YES, SIML) SIOL reads SVAL and VAL takes it, after SDLY when SDLY >= 0 (base 7's).
struct EventRecord : Record {
    using Record::Record;
    char val[40] = {}, sval[40] = {};
    Link inp;
    Simulation sim;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* sval_fd = type().find("SVAL");
    const FieldDesc* simm_fd = type().find("SIMM");
    static std::vector<FieldDesc> fields() {
        using R = EventRecord;
        auto v = common_fields();
        auto add = {BEAMCTL_FIELD(R, VAL, val, String, kVal), BEAMCTL_FIELD(R, INP, inp, InLink, 0),
                    BEAMCTL_FIELD(R, SVAL, sval, String, 0)};
        v.insert(v.end(), add.begin(), add.end());
        add_simulation_fields<R>(v, false, false);
        return v;
    }
    void init() override {
        sim_init(*this, sim, *simm_fd);
        load_constant(sim.siol, *sval_fd);
        if (load_constant(inp, *val_fd)) udf = 0;
    }
    PutStatus special(const FieldDesc& f) override {
        sim_special(*this, sim, f, simm_fd);
        return PutStatus::Ok;
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        if (step == SimStep::Now) {
            if (read_link(sim.siol, *sval_fd) || sim.siol.kind != Link::Kind::Db) {
                std::memcpy(val, sval, sizeof val);
                udf = 0;
            }
        } else if (soft_read(*this, inp, *val_fd)) {
            udf = 0;
        }
        if (val[0] && database()) database()->post_event(std::string_view(val, strnlen(val, sizeof val)));
        stamp_time();
        unsigned m = reset_alarms();
        post(val_fd, kDbeValue | kDbeLog | m);
        pact = 0;
        return ProcessResult::Done;
    }
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }
};

} // namespace

void register_logic_records(RecordTypes& types) {
    add_type<CalcRecord>(types, "calc");
    add_type<CalcoutRecord>(types, "calcout");
    add_type<SeqRecord>(types, "seq");
    add_type<FanoutRecord>(types, "fanout");
    add_type<DfanoutRecord>(types, "dfanout");
    add_type<SelRecord>(types, "sel");
    add_type<EventRecord>(types, "event");
}

} // namespace beamctl::pv
