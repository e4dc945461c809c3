#include "pv/record.hpp"
#include "pv/record_pool.hpp"

#include "core/error.hpp"
#include "pv/convert.hpp"
#include "pv/database.hpp"
#include "pv/motor_record.hpp"

#include <algorithm>
#include <cfloat>

namespace beamctl::pv {

const Menu kMenuScan{"menuScan",
                     {"Passive", "Event", "I/O Intr", "10 second", "5 second", "2 second",
                      "1 second", ".5 second", ".2 second", ".1 second"}};
const Menu kMenuPini{"menuPini", {"NO", "YES", "RUN", "RUNNING", "PAUSE", "PAUSED"}};
const Menu kMenuAlarmSevr{"menuAlarmSevr", {"NO_ALARM", "MINOR", "MAJOR", "INVALID"}};
const Menu kMenuAlarmStat{"menuAlarmStat",
                          {kStatusNames[0], kStatusNames[1], kStatusNames[2], kStatusNames[3],
                           kStatusNames[4], kStatusNames[5], kStatusNames[6], kStatusNames[7],
                           kStatusNames[8], kStatusNames[9], kStatusNames[10], kStatusNames[11],
                           kStatusNames[12], kStatusNames[13], kStatusNames[14], kStatusNames[15],
                           kStatusNames[16], kStatusNames[17], kStatusNames[18], kStatusNames[19],
                           kStatusNames[20], kStatusNames[21]}};
const Menu kMenuYesNo{"menuYesNo", {"NO", "YES"}};
const Menu kMenuFtype{"menuFtype", {"STRING", "CHAR", "UCHAR", "SHORT", "USHORT", "LONG", "ULONG",
                                    "INT64", "UINT64", "FLOAT", "DOUBLE", "ENUM"}};
const Menu kMenuPostOnChange{"stringinPOST", {"On Change", "Always"}};
const Menu kMenuPostAlways{"waveformPOST", {"Always", "On Change"}};
const Menu kMenuOmsl{"menuOmsl", {"supervisory", "closed_loop"}};
const Menu kMenuIvoa{"menuIvoa",
                     {"Continue normally", "Don't drive outputs", "Set output to IVOV"}};
// "beamctl": links with "@address" reach the engine's signals (an IOC's device support); the
// asyn names are ecmccfg's, whose "@asyn(...)...ec0.s3.entry?" addresses mean the same there.
// base's soft device supports (devSoft.dbd) follow; asyn's other interfaces (ecmccfg's templates
// name them) are choices too: such a record needs its "@" address bound by the IOC.
const Menu kMenuSoftDtyp{"DTYP",
                         {"Soft Channel", "beamctl", "asynInt32", "asynFloat64", "asynUInt32Digital",
                          "Raw Soft Channel", "Async Soft Channel", "Soft Timestamp", "getenv", "stdio",
                          "asynInt64", "asynInt8ArrayIn", "asynInt8ArrayOut", "asynInt16ArrayIn",
                          "asynInt16ArrayOut", "asynInt32ArrayIn", "asynInt32ArrayOut", "asynInt64ArrayIn",
                          "asynInt64ArrayOut", "asynFloat32ArrayIn", "asynFloat32ArrayOut",
                          "asynFloat64ArrayIn", "asynFloat64ArrayOut", "asynOctetRead", "asynOctetWrite",
                          "asynOctetWriteRead", "asynOctetCmdResponse", "asynOctetWriteBinary",
                          "asynInt32Average", "asynFloat64Average", "asynInt32TimeSeries",
                          "asynFloat64TimeSeries", "General Time", "Db State", "IOC stats", "IOC stats clusts",
                          "IOC env var", "IOC epics var"}};

bool soft_dtyp(uint16_t dtyp) {
    return dtyp == kDtypSoft || dtyp == kDtypRawSoft || dtyp == kDtypAsyncSoft;
}

const char* dtyp_refusal(std::string_view type, uint16_t dtyp) {
    // base's devSoft.dbd: which record types have which of its device supports
    auto in = [&](std::initializer_list<std::string_view> types) {
        for (auto t : types)
            if (t == type) return true;
        return false;
    };
    switch (dtyp) {
    case kDtypRawSoft:
        if (in({"ai", "ao", "bi", "bo", "mbbi", "mbbo", "mbbiDirect", "mbboDirect"})) return nullptr;
        return "has no \"Raw Soft Channel\" device support (base has it for ai ao bi bo mbbi mbbo mbbiDirect "
               "mbboDirect)";
    case kDtypAsyncSoft:
        if (in({"ai", "ao", "bi", "bo", "calcout", "int64in", "int64out", "longin", "longout", "lso", "mbbi",
                "mbbiDirect", "mbbo", "mbboDirect", "printf", "stringin", "stringout"}))
            return nullptr;
        return "has no \"Async Soft Channel\" device support";
    case kDtypTimestamp:
        if (in({"ai", "stringin"})) return nullptr;
        return "has no \"Soft Timestamp\" device support (base has it for ai and stringin)";
    case kDtypGetenv:
        if (in({"stringin", "lsi"})) return nullptr;
        return "has no \"getenv\" device support (base has it for stringin and lsi)";
    case kDtypStdio:
        if (in({"stringout", "lso", "printf"})) return nullptr;
        return "has no \"stdio\" device support (base has it for stringout, lso and printf)";
    case kDtypIocStats: // devIocStats (pv/ioc_stats.hpp)
        if (in({"ai", "ao", "stringin", "waveform"})) return nullptr;
        return "has no \"IOC stats\" device support (devIocStats has it for ai ao stringin waveform)";
    case kDtypIocStatsClusts:
        return "device support \"IOC stats clusts\" (RTEMS/vxWorks network buffer pools) has no source on Linux";
    case kDtypIocEnvVar:
    case kDtypIocEpicsVar:
        if (type == "stringin") return nullptr;
        return "has no \"IOC env var\" / \"IOC epics var\" device support (devIocStats has them for stringin)";
    case kDtypGeneralTime:
    case kDtypDbState:
        return "device support \"General Time\" / \"Db State\" is not provided by beamctl";
    default: return nullptr;
    }
}
bool has_device_support(std::string_view type) {
    for (const char* t : {"aSub", "calc", "compress", "dfanout", "fanout", "permissive", "sel", "seq", "state", "sub"})
        if (type == t) return false;
    return true;
}
const Menu kMenuPriority{"menuPriority", {"LOW", "MEDIUM", "HIGH"}};
const Menu kMenuOif{"aoOIF", {"Full", "Incremental"}};

void copy_string(char* dst, std::size_t size, std::string_view src) {
    std::size_t n = std::min(src.size(), size - 1);
    if (n) std::memcpy(dst, src.data(), n); // an empty view may have no data pointer
    std::memset(dst + n, 0, size - n);
}

RecordType::RecordType(std::string name, std::vector<FieldDesc> fields,
                       std::function<std::unique_ptr<Record>(const RecordType&)> factory)
    : name_(std::move(name)), fields_(std::move(fields)), factory_(std::move(factory)) {
    for (std::size_t i = 0; i < fields_.size(); ++i) {
        fields_[i].index = int(i);
        if (!by_name_.emplace(fields_[i].name, &fields_[i]).second)
            throw Error(SB() << "record type " << name_ << ": field " << fields_[i].name
                             << " defined twice");
    }
}

const FieldDesc* RecordType::find(std::string_view field) const {
    auto it = by_name_.find(field);
    return it == by_name_.end() ? nullptr : it->second;
}

RecordTypes& RecordTypes::global() {
    static RecordTypes* types = [] {
        auto* t = new RecordTypes;
        register_standard_records(*t);
        register_logic_records(*t);
        register_more_records(*t);
        register_array_records(*t);
        register_misc_records(*t);
        register_sub_records(*t);
        register_motor_record(*t);
        return t;
    }();
    return *types;
}

void RecordTypes::add(std::unique_ptr<RecordType> t) {
    std::string n = t->name();
    if (!types_.emplace(n, std::move(t)).second)
        throw Error(SB() << "record type " << n << " registered twice");
}

const RecordType* RecordTypes::find(std::string_view name) const {
    auto it = types_.find(std::string(name));
    return it == types_.end() ? nullptr : it->second.get();
}

std::vector<std::string> RecordTypes::names() const {
    std::vector<std::string> v;
    for (auto& [n, t] : types_) v.push_back(n);
    std::sort(v.begin(), v.end());
    return v;
}

Record::Record(const RecordType& type) : type_(type) {}
void* Record::operator new(std::size_t size) { return record_pool::allocate(size); }
void Record::operator delete(void* p, std::size_t size) { record_pool::deallocate(p, size); }
Record::~Record() = default;

std::vector<FieldDesc> Record::common_fields() {
    using R = Record;
    return {
        BEAMCTL_FIELD(R, NAME, name_, String, kReadOnly),
        BEAMCTL_FIELD(R, DESC, desc, String, 0),
        BEAMCTL_FIELD(R, ASG, asg, String, 0),
        BEAMCTL_MENU(R, SCAN, scan, kMenuScan, kScanField),
        BEAMCTL_MENU(R, PINI, pini, kMenuPini, 0),
        BEAMCTL_FIELD(R, PHAS, phas, Short, kScanField),
        BEAMCTL_FIELD(R, EVNT, evnt, String, kScanField),
        BEAMCTL_FIELD(R, TSE, tse, Short, 0),
        BEAMCTL_FIELD(R, TSEL, tsel, InLink, 0),
        BEAMCTL_MENU(R, DTYP, dtyp, kMenuSoftDtyp, kInitOnly),
        BEAMCTL_FIELD(R, DISV, disv, Short, 0),
        BEAMCTL_FIELD(R, DISA, disa, Short, 0),
        BEAMCTL_FIELD(R, SDIS, sdis, InLink, 0),
        BEAMCTL_FIELD(R, DISP, disp, UChar, 0),
        BEAMCTL_MENU(R, DISS, diss, kMenuAlarmSevr, 0),
        BEAMCTL_FIELD(R, PROC, proc, UChar, kProcess | kAsl0 | kProcField),
        BEAMCTL_MENU(R, STAT, stat, kMenuAlarmStat, kReadOnly),
        BEAMCTL_MENU(R, SEVR, sevr, kMenuAlarmSevr, kReadOnly),
        BEAMCTL_MENU(R, NSTA, nsta, kMenuAlarmStat, kReadOnly),
        BEAMCTL_MENU(R, NSEV, nsev, kMenuAlarmSevr, kReadOnly),
        BEAMCTL_MENU(R, ACKS, acks, kMenuAlarmSevr, kReadOnly),
        BEAMCTL_MENU(R, ACKT, ackt, kMenuYesNo, 0),
        BEAMCTL_FIELD(R, UDF, udf, UChar, kProcess),
        BEAMCTL_MENU(R, UDFS, udfs, kMenuAlarmSevr, 0),
        BEAMCTL_FIELD(R, LCNT, lcnt, UChar, kReadOnly),
        BEAMCTL_FIELD(R, PACT, pact, UChar, kReadOnly),
        BEAMCTL_FIELD(R, PUTF, putf, UChar, kReadOnly),
        BEAMCTL_FIELD(R, RPRO, rpro, UChar, kReadOnly),
        BEAMCTL_MENU(R, PRIO, prio, kMenuPriority, 0),
        BEAMCTL_FIELD(R, TPRO, tpro, UChar, 0),
        BEAMCTL_FIELD(R, FLNK, flnk, FwdLink, 0),
        BEAMCTL_FIELD(R, AMSG, amsg, String, kReadOnly),
        BEAMCTL_FIELD(R, NAMSG, namsg, String, kReadOnly),
        BEAMCTL_FIELD(R, UTAG, utag, UInt64, kReadOnly),
    };
}

Elements Record::elements(const FieldDesc& f) {
    uint16_t stride = f.size;
    return Elements{f.dbf, f.addr(*this), 1, 1, stride};
}

int Record::enum_strings(const FieldDesc& f, const char* out[kEnumStates]) const {
    if (!f.menu) return 0;
    int n = int(std::min<std::size_t>(f.menu->choices.size(), kEnumStates));
    for (int i = 0; i < n; ++i) out[i] = f.menu->choices[i];
    return n;
}

namespace {
void type_range(Dbf t, double& hi, double& lo) {
    switch (t) { // recGbl getMaxRangeValues
    case Dbf::Char: hi = 127; lo = -128; break;
    case Dbf::UChar: hi = 255; lo = 0; break;
    case Dbf::Short: hi = 32767; lo = -32768; break;
    case Dbf::UShort: hi = 65535; lo = 0; break;
    // enum and menu fields: no limits (EPICS base serves 0..0 for them; bo's VAL has control
    // limits, set by its record type)
    case Dbf::Long: hi = 2147483647.0; lo = -2147483648.0; break;
    case Dbf::ULong: hi = 4294967295.0; lo = 0; break;
    case Dbf::Int64: hi = 9223372036854775807.0; lo = -9223372036854775808.0; break;
    case Dbf::UInt64: hi = 18446744073709551615.0; lo = 0; break;
    case Dbf::Float: hi = 1e30; lo = -1e30; break;
    case Dbf::Double: hi = 1e300; lo = -1e300; break;
    default: hi = lo = 0;
    }
}
} // namespace

void Record::metadata(const FieldDesc& f, Metadata& md) const {
    type_range(f.dbf, md.disp_hi, md.disp_lo);
    md.ctrl_hi = md.disp_hi;
    md.ctrl_lo = md.disp_lo;
    md.precision = precision(f);
}

int16_t Record::precision(const FieldDesc& f) const {
    // dbConvert's getDoubleString starts from 6; a record type without get_precision keeps it,
    // and recGblGetPrec keeps it too (record types override this where base's get_precision acts)
    return (f.dbf == Dbf::Float || f.dbf == Dbf::Double) ? 6 : 0;
}

bool Record::set_sevr(uint16_t new_stat, uint16_t new_sevr, std::string_view msg) {
    if (nsev < new_sevr) {
        nsta = new_stat;
        nsev = new_sevr;
        if (msg.empty()) namsg[0] = 0;
        else copy_string(namsg, sizeof namsg, msg);
        return true;
    }
    return false;
}

unsigned Record::reset_alarms() {
    uint16_t prev_stat = stat, prev_sevr = sevr;
    unsigned stat_mask = 0;
    if (std::strncmp(namsg, amsg, sizeof amsg) != 0) { // recGblResetAlarms: AMSG follows NAMSG
        std::memcpy(amsg, namsg, sizeof amsg);
        stat_mask = kDbeAlarm;
    }
    stat = nsta;
    sevr = nsev;
    nsta = 0;
    nsev = 0;
    if (prev_sevr != sevr) {
        stat_mask = kDbeAlarm;
        post("SEVR", kDbeValue);
    }
    if (prev_stat != stat) stat_mask |= kDbeValue;
    if (!stat_mask) return 0;
    post("STAT", stat_mask);
    post("AMSG", stat_mask);
    if (!ackt || sevr >= acks) {
        acks = sevr;
        post("ACKS", kDbeValue);
    }
    return kDbeAlarm;
}

void Record::post(const FieldDesc* f, unsigned mask) {
    if (db_) db_->post(*this, f, mask);
}

void Record::post(const char* field, unsigned mask) {
    if (!db_) return;
    if (const FieldDesc* f = type_.find(field)) db_->post(*this, f, mask);
}

void Record::async_done(PutStatus st) {
    pact = 0;
    if (db_) db_->async_complete(*this, st);
}

void Record::call_after(double seconds, int tag) {
    if (db_) db_->call_after(*this, seconds, tag);
}

void Record::rescan() {
    if (db_) db_->rescan(*this);
}

void Record::init_error(const std::string& why) {
    if (db_) db_->note_record_error(*this, why);
}

void Record::stamp_time() {
    if (tse == -2) return;
    if (tsel.kind == Link::Kind::Db && tsel.target()) {
        time = tsel.target()->time;
        return;
    }
    time = EpicsTime::now();
}

void Record::inherit_sevr(uint8_t ms, uint16_t new_stat, uint16_t new_sevr) {
    switch (ms) {
    case Link::kMsi:
        if (new_sevr < kInvalid) break;
        [[fallthrough]];
    case Link::kMs: set_sevr(kStatLink, new_sevr); break;
    case Link::kMss: set_sevr(new_stat, new_sevr); break;
    default: break;
    }
}

bool Record::read_link(Link& l, const FieldDesc& f) { return db_ ? db_->link_read(*this, l, f) : l.kind != Link::Kind::Db; }
bool Record::read_link(Link& l, double& v) { return db_ ? db_->link_read(*this, l, v) : l.kind != Link::Kind::Db; }
bool Record::write_link(Link& l, const FieldDesc& f) { return db_ ? db_->link_write(*this, l, f) : l.kind != Link::Kind::Db; }
bool Record::write_link(Link& l, double v) { return db_ ? db_->link_write(*this, l, v) : l.kind != Link::Kind::Db; }
void Record::fwd_link(Link& l) {
    if (db_) db_->link_forward(*this, l);
}

bool Record::load_constant(const Link& link, double& v) {
    if (link.kind != Link::Kind::Constant) return false;
    const LinkSpec& l = link.s();
    if (!l.numbers.empty()) {
        v = l.numbers[0];
        return true;
    }
    if (l.is_string_constant) return parse_double(l.string_constant, v);
    return false;
}

bool Record::load_constant(const Link& link, const FieldDesc& f) {
    if (link.kind != Link::Kind::Constant) return false;
    const LinkSpec& l = link.s();
    Elements e = elements(f);
    if (l.is_string_constant && l.numbers.empty()) {
        char buf[kStringSize];
        copy_string(buf, sizeof buf, l.string_constant);
        return put_element(*this, f, e, 0, Prim::String, buf);
    }
    if (l.numbers.empty()) return false;
    if (f.flags & kArray) {
        uint32_t n = std::min<uint32_t>(uint32_t(l.numbers.size()), e.capacity);
        for (uint32_t k = 0; k < n; ++k) put_element(*this, f, e, k, Prim::Double, &l.numbers[k]);
        set_count(f, n);
        return true;
    }
    return put_element(*this, f, e, 0, Prim::Double, &l.numbers[0]);
}

} // namespace beamctl::pv
