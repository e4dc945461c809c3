// Record model of the PV database: field descriptors, record types and the Record base class that
// every record type implements (ai/ao/... here; motor, mca, epid, axis PVs in later subsystems).
// Threading: records are owned by one Database and touched only on its thread (the IOC loop).
#pragma once

#include "pv/link.hpp"
#include "pv/types.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace beamctl::pv {

class Record;
class Database;

// A fixed set of choices for a DBF_MENU field (menuScan, menuAlarmSevr, ...).
struct Menu {
    const char* name;
    std::vector<const char*> choices;
};
// DTYP choices of kMenuSoftDtyp with a meaning of their own (their index in the menu).
enum SoftDtyp : uint16_t {
    kDtypSoft = 0, kDtypBeamctl = 1, kDtypRawSoft = 5, kDtypAsyncSoft = 6, kDtypTimestamp = 7,
    kDtypGetenv = 8, kDtypStdio = 9, kDtypGeneralTime = 32, kDtypDbState = 33,
    kDtypIocStats = 34, kDtypIocStatsClusts = 35, kDtypIocEnvVar = 36, kDtypIocEpicsVar = 37,
};
// A devIocStats device support (IocStats binds its "@parameter" addresses).
inline bool ioc_stats_dtyp(uint16_t dtyp) { return dtyp >= kDtypIocStats && dtyp <= kDtypIocEpicsVar; }
// A soft device support (no "@" address: Soft Channel, Raw Soft Channel, Async Soft Channel).
bool soft_dtyp(uint16_t dtyp);
// Why record type `type` cannot have DTYP choice `dtyp` of kMenuSoftDtyp (as base's devSoft.dbd
// lists them), or nullptr when it can.
const char* dtyp_refusal(std::string_view type, uint16_t dtyp);
// False for base's record types that have no device support (calc, seq, sub, ...): their DTYP
// reads as an empty string, as a DBF_DEVICE field with no choices does in base.
bool has_device_support(std::string_view type);
extern const Menu kMenuScan, kMenuPini, kMenuAlarmSevr, kMenuAlarmStat, kMenuYesNo, kMenuFtype,
    kMenuPostOnChange, kMenuPostAlways, kMenuOmsl, kMenuIvoa, kMenuSoftDtyp, kMenuPriority, kMenuOif;

enum FieldFlag : uint16_t {
    kReadOnly = 1 << 0, // SPC_NOMOD: never writable (not even from a .db file)
    kProp = 1 << 1,     // metadata: a change posts DBE_PROPERTY to every monitor of the record
    kProcess = 1 << 2,  // pp(TRUE): a put processes the record
    kAsl0 = 1 << 3,     // access-security level 0 (VAL-like); all others are level 1
    kArray = 1 << 4,    // element storage is provided by Record::elements() (waveform VAL)
    kInitOnly = 1 << 5, // settable from a .db file but read-only over CA (NELM, FTVL)
    kEgu = 1 << 6,      // reports the record's EGU as units
    kDisplayHopr = 1 << 7, // display limits are HOPR/LOPR (VAL and the alarm limits)
    kScanField = 1 << 8,   // SCAN, PHAS, EVNT: a put moves the record to another scan list
    kProcField = 1 << 9,   // PROC: a put or a link to it always processes the record
    // A long string (lsi, lso and printf VAL/OVAL; a kArray of chars): over CA one DBF_STRING, its
    // first 39 characters and no element while LEN is 0 (their cvt_dbaddr and get_array_info);
    // "FIELD$" is the char array whole.
    kLongString = 1 << 10,
};

// Describes one field of a record type. `addr` returns the storage of that field in a record.
struct FieldDesc {
    const char* name;
    Dbf dbf;
    uint16_t flags;
    uint16_t size; // bytes of storage (the char array size for DBF_STRING)
    const Menu* menu;
    void* (*addr)(Record&);
    int index = -1; // position in the record type's table
};

// Declares a field whose storage is member `m` of record class R.
#define BEAMCTL_FIELD(R, NAME, m, dbf, flags)                                                      \
    ::beamctl::pv::FieldDesc {                                                                     \
        #NAME, ::beamctl::pv::Dbf::dbf, uint16_t(flags), uint16_t(sizeof(R::m)), nullptr,          \
            [](::beamctl::pv::Record& r) -> void* { return &static_cast<R&>(r).m; }                \
    }
#define BEAMCTL_MENU(R, NAME, m, menu, flags)                                                      \
    ::beamctl::pv::FieldDesc {                                                                     \
        #NAME, ::beamctl::pv::Dbf::Menu, uint16_t(flags), uint16_t(sizeof(R::m)), &menu,           \
            [](::beamctl::pv::Record& r) -> void* { return &static_cast<R&>(r).m; }                \
    }

// A record type: its name, fields and factory. Registered once in the RecordTypes registry.
class RecordType {
public:
    RecordType(std::string name, std::vector<FieldDesc> fields,
               std::function<std::unique_ptr<Record>(const RecordType&)> factory);
    const std::string& name() const { return name_; }
    const std::vector<FieldDesc>& fields() const { return fields_; }
    const FieldDesc* find(std::string_view field) const;
    std::unique_ptr<Record> create() const { return factory_(*this); }

private:
    std::string name_;
    std::vector<FieldDesc> fields_;
    std::unordered_map<std::string_view, const FieldDesc*> by_name_;
    std::function<std::unique_ptr<Record>(const RecordType&)> factory_;
};

// Registry of record types by name ("ai", "motor", ...). Filled before databases are loaded.
class RecordTypes {
public:
    static RecordTypes& global(); // holds the standard types (see register_standard_records)
    void add(std::unique_ptr<RecordType> t);
    const RecordType* find(std::string_view name) const;
    std::vector<std::string> names() const;

private:
    std::unordered_map<std::string, std::unique_ptr<RecordType>> types_;
};
void register_standard_records(RecordTypes& types); // ai ao bi bo longin ... waveform
void register_logic_records(RecordTypes& types);    // calc calcout seq fanout dfanout sel event
void register_more_records(RecordTypes& types);     // mbbiDirect mbboDirect int64in int64out ...
void register_array_records(RecordTypes& types);    // aai aao subArray compress histogram
void register_misc_records(RecordTypes& types);     // permissive state printf
void register_sub_records(RecordTypes& types);      // sub aSub (routines from dlload libraries)

// A view of a field's elements: scalars have count == capacity == 1.
struct Elements {
    Dbf type;
    void* data;
    uint32_t count;    // valid elements now (NORD for arrays)
    uint32_t capacity; // maximum elements (NELM)
    uint16_t stride;   // bytes per element
};

// Metadata of a field as Channel Access GR/CTRL types report it.
struct Metadata {
    const char* units = "";
    int16_t precision = 0;
    double disp_hi = 0, disp_lo = 0;
    double alarm_hihi = NAN, alarm_high = NAN, alarm_low = NAN, alarm_lolo = NAN;
    double ctrl_hi = 0, ctrl_lo = 0;
};

// Outcome of processing: synchronous, or completion reported later via Record::async_done().
enum class ProcessResult : uint8_t { Done, Async };

// Base of every record. Common fields (dbCommon) live here; subclasses add their own and
// implement process(). All calls happen on the owning database's thread.
class Record {
public:
    explicit Record(const RecordType& type);
    virtual ~Record();
    Record(const Record&) = delete;
    Record& operator=(const Record&) = delete;
    // Records live in blocks of their own (pv/record_pool.hpp: a large database stays packed).
    static void* operator new(std::size_t size);
    static void operator delete(void* p, std::size_t size);

    const RecordType& type() const { return type_; }
    std::string_view name() const { return name_; }
    Database* database() const { return db_; }

    // --- behaviour, implemented by record types ---
    // Called once after the .db fields are applied; throws Error for inconsistent settings.
    virtual void init() {}
    // Record processing: alarms, outputs, timestamp, monitors.
    virtual ProcessResult process() = 0;
    // Called after a field was written over CA (before processing, if the field processes).
    // May refuse the value by returning a status other than Ok (the old value is restored).
    virtual PutStatus special(const FieldDesc& f) {
        (void)f;
        return PutStatus::Ok;
    }
    // Elements of a field; the default is the scalar at f.addr.
    virtual Elements elements(const FieldDesc& f);
    // Sets the number of valid elements of an array field after a put (NORD).
    virtual void set_count(const FieldDesc& f, uint32_t n) {
        (void)f;
        (void)n;
    }
    // State strings of a DBF_ENUM field; returns the number of states (no_str).
    virtual int enum_strings(const FieldDesc& f, const char* out[kEnumStates]) const;
    // CA metadata of field f. The default: no units, type range, NaN alarm limits.
    virtual void metadata(const FieldDesc& f, Metadata& md) const;
    // Precision used to format a float/double field as a string (PREC).
    virtual int16_t precision(const FieldDesc& f) const;
    // A record that polls its device (the motor record) returns its period; the database then
    // calls poll_tick() that often, independent of SCAN.
    virtual double poll_period_s() const { return 0; }
    virtual void poll_tick() {}
    // A delay the record asked for with call_after() has passed (calcout ODLY, seq DLYn).
    virtual void on_delay() {}
    // The same for a delay asked for with a tag (bo HIGH, simulation's SDLY: one record, two
    // kinds of delay); tag 0 is on_delay().
    virtual void on_delay(int tag) {
        if (tag == 0) on_delay();
    }
    // Asks the database to call on_delay(tag) after `seconds` of its clock (scan_periodic's time).
    void call_after(double seconds, int tag = 0);
    // Moves the record to the scan list of its SCAN field (simulation mode's SSCN swap).
    void rescan();
    // init(): this record cannot work as configured, but the database loads (as EPICS's
    // recGblRecordError at iocInit): the error is kept in Database::record_errors and logged.
    void init_error(const std::string& why);

    // --- alarm helpers (recGbl) ---
    // Raises the new alarm if `sevr` is above the pending one (recGblSetSevr); the alarm message
    // (AMSG after processing) is `msg`, or empty.
    bool set_sevr(uint16_t stat, uint16_t sevr, std::string_view msg = {});
    // Moves the pending alarm into STAT/SEVR, posts them; returns DBE_ALARM if they changed.
    unsigned reset_alarms();
    // The record's timestamp: now, or TSEL's record's (a database link), or left to device
    // support (TSE -2).
    void stamp_time();
    // Posts a monitor event on field `f` (nullptr: every field, for DBE_PROPERTY).
    void post(const FieldDesc* f, unsigned mask);
    void post(const char* field, unsigned mask);
    // An Async process() ends: completes put-callbacks waiting on this record (and the
    // put-callback of a record whose processing led here). Forward links of an asynchronous
    // record are its own job: call fwd_link(flnk) first, as recGblFwdLink.
    void async_done(PutStatus st = PutStatus::Ok);
    bool busy() const { return pact; }

    // --- links (dbGetLink, dbPutLink, dbScanFwdLink), for process() of record types ---
    // Reads link l into field f of this record (an array field: as many elements as fit, NORD
    // set). An empty or constant link reads nothing (constants are loaded at init by
    // load_constant) and returns true. A database link with PP processes a Passive target first;
    // MS/MSS/MSI raise this record's pending alarm from the target's. Returns false when no value
    // could be read (this record's pending alarm is then LINK/INVALID).
    bool read_link(Link& l, const FieldDesc& f);
    bool read_link(Link& l, double& v);
    // Writes field f of this record (or v) through link l: PP processes a Passive target, a link
    // to PROC always processes it; MS/MSS/MSI give the target this record's pending alarm.
    // Returns false if refused (this record's pending alarm is then LINK/INVALID).
    bool write_link(Link& l, const FieldDesc& f);
    bool write_link(Link& l, double v);
    // Loads a constant link into field f (or v), at init; true if the link held a value.
    bool load_constant(const Link& l, const FieldDesc& f);
    bool load_constant(const Link& l, double& v);
    // Processes the target of a forward link if it is Passive (FLNK, LNKn of seq/fanout).
    void fwd_link(Link& l);
    // recGblInheritSevr: raise the pending alarm from another record's by an MS mode.
    void inherit_sevr(uint8_t ms, uint16_t stat, uint16_t sevr);
    // The info(name, "value") items of the record's .db definition, in order.
    const std::vector<std::pair<std::string, std::string>>& infos() const { return info_; }
    // Field descriptor by name (nullptr if the type has none).
    const FieldDesc* field(std::string_view name) const { return type_.find(name); }

    // Set by the code that owns a record's value (a bus, an axis): called after a client's put was
    // stored and accepted by special(), before processing. Returning other than Ok refuses the put
    // (the old value is restored). Example: an output PV forwards the value to the RT cycle.
    std::function<PutStatus(Record&, const FieldDesc&)> put_hook;
    // Set when VAL belongs to the system (an input from the bus): clients get no write right on it.
    bool val_read_only = false;

    // --- dbCommon fields ---
    char name_[61] = {};
    char desc[41] = {};
    char asg[29] = {};
    uint16_t scan = 0, pini = 0, dtyp = 0;
    int16_t phas = 0, disv = 1, disa = 0;
    uint16_t diss = 0;
    uint8_t proc = 0, pact = 0, udf = 1, tpro = 0;
    uint16_t stat = kStatUdf, sevr = kInvalid, nsta = 0, nsev = 0, acks = 0, ackt = 1;
    uint16_t udfs = kInvalid;
    EpicsTime time;
    char evnt[40] = {};  // event name for SCAN=Event
    int16_t tse = 0;     // time stamp event (0: now; -2: set by device support)
    Link tsel;           // time stamp link
    Link sdis;           // disable link: read into DISA before processing
    uint8_t disp = 0;    // 1: puts from clients to fields other than DISP are refused
    uint8_t putf = 0, rpro = 0, lcnt = 0;
    uint16_t prio = 0;   // scan priority LOW/MEDIUM/HIGH (one scan thread here: informational)
    Link flnk;           // forward link: processed after this record
    char amsg[40] = {};  // alarm message of STAT/SEVR (recGblSetSevrMsg)
    char namsg[40] = {}; // pending alarm message (NSTA/NSEV)
    uint64_t utag = 0;   // user tag (DBF_UINT64): device support sets it

    static std::vector<FieldDesc> common_fields(); // dbCommon part of every type's table

private:
    friend class Database;
    const RecordType& type_;
    Database* db_ = nullptr;
    std::vector<class Subscription*> subs_;        // monitors on any field of this record
    std::vector<class RecordObserver*> observers_; // channels, told when the record is removed
    std::unique_ptr<struct NotifyState> notify_;   // put-callback in progress and queued ones
    std::vector<std::pair<std::string, std::string>> info_; // info(name, "value") items
    std::vector<std::string> aliases_;
    // processing bookkeeping (Database::process_record)
    struct PutNotify* pn_ = nullptr; // the put-callback this record's async completion belongs to
    bool initialised_ = false;       // init_records ran init() (its links are resolved)
    bool in_process_ = false;        // inside process()
    bool done_in_process_ = false;   // async_done() was called inside process()
    bool link_wait_ = false;         // an Async Soft Channel put over CA waits for its completion
    PutStatus done_status_ = PutStatus::Ok;
};

// Helpers for record implementations.
template <typename T> T& field_ref(Record& r, const FieldDesc& f) {
    return *static_cast<T*>(f.addr(r));
}
void copy_string(char* dst, std::size_t size, std::string_view src); // truncating, NUL-terminated
// The text of link field l of record r as clients read it (Link::canonical, or the text still
// waiting in the database for init_records).
std::string link_text(const Record& r, const Link& l);

} // namespace beamctl::pv
