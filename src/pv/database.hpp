// The process-variable database: records by name, channel addresses ("rec.FIELD$"), puts with
// completion callbacks applied in arrival order, gets with conversion, monitors, .db import/export.
// Threading: one thread owns a Database (the IOC loop); other threads hand work to that thread.
#pragma once

#include "pv/db_file.hpp"
#include "pv/record.hpp"
#include "pv/record_index.hpp"

#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <ostream>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace beamctl::pv {

// A resolved channel name: one field of one record, seen as `count` elements of type `native`.
struct Address {
    // Field: the field as it is; LongString: "FIELD$" of a DBF_STRING field, its chars as an array;
    // StringHead: a kLongString char array read without '$', one DBF_STRING; RecordType: ".RTYP".
    enum class Kind : uint8_t { Field, LongString, StringHead, RecordType };
    Record* rec = nullptr;
    const FieldDesc* field = nullptr; // nullptr for Kind::RecordType (".RTYP")
    Kind kind = Kind::Field;
    Prim native = Prim::Double;
    uint32_t count = 1; // maximum elements
    bool writable() const;
    int asl() const; // access-security level of the field
};

// Receives monitor events of one field. on_event runs on the database thread, synchronously
// inside the post; it must only copy/encode the value and return.
class Subscription {
public:
    Address addr;
    unsigned mask = kDbeValue | kDbeAlarm;
    virtual ~Subscription() = default;
    virtual void on_event(unsigned mask) = 0;
};

// Told when a record is removed from the database (e.g. a retired RCP object).
class RecordObserver {
public:
    virtual ~RecordObserver() = default;
    virtual void on_record_removed(Record& r) = 0;
};

using PutCallback = std::function<void(PutStatus)>;

// Put-callback bookkeeping of one record: the active put and those waiting behind it.
struct NotifyState {
    struct Queued {
        Address addr;
        Prim type;
        std::vector<char> data;
        uint32_t count;
        PutCallback cb;
    };
    PutCallback active;
    std::deque<Queued> queue;
};

// One put-callback whose completion waits for every asynchronous record its processing reached
// (through forward links and PP output links), as EPICS dbNotify.
struct PutNotify {
    Record* origin = nullptr; // the record the client wrote to; its NotifyState holds the callback
    int pending = 0;          // asynchronous records still busy
    bool started = false;     // the synchronous part of the processing has returned
    PutStatus status = PutStatus::Ok;
};

struct DatabaseStats {
    uint64_t puts = 0, gets = 0, posts = 0, processes = 0, bad_puts = 0;
    uint64_t link_errors = 0; // link reads/writes that failed (LINK alarm raised)
};

// Binds the hardware address of a link ("@ec0.s3.positionActual01") to a device; returns nullptr
// with *why when it cannot. Called by init_records for every "@..." link.
using LinkBinder = std::function<LinkDevice*(Record&, const FieldDesc&, Link&, std::string* why)>;
// Makes the Channel Access link of a link to a record of another server (owned by the binder's
// owner, told release() when the database lets it go); returns nullptr with *why when it cannot.
using RemoteBinder = std::function<RemoteLink*(Record&, const FieldDesc&, Link&, std::string* why)>;

class IocStats;

class Database {
public:
    Database();
    ~Database();
    Database(const Database&) = delete;
    Database& operator=(const Database&) = delete;

    // Loads records from a parsed .db file. Throws Error("file:line:col: ...") on the first bad
    // record or field; records of a file that fails are not added.
    void load(const DbFile& file, const RecordTypes& types = RecordTypes::global());
    // Adds a record created by a subsystem; its fields must already be set.
    Record& add(std::unique_ptr<Record> rec);
    void add_alias(std::string_view record, std::string_view alias);
    // Removes a record: channels on it are told (they disconnect their clients).
    void remove(std::string_view name);
    // Resolves the links of records not yet initialised (every error at once, with file:line:col,
    // as a MultiError), runs their init(), loads constant links, puts them on their scan lists and
    // processes those with PINI YES/RUN/RUNNING in PHAS order.
    void init_records();
    void set_link_binder(LinkBinder b) { binder_ = std::move(b); }
    // Links with CA/CP/CPP to records not in this database become CA links through b (an IOC
    // installs its CA client here); without a remote binder they are load errors.
    void set_remote_binder(RemoteBinder b) { remote_binder_ = std::move(b); }
    // Called by init_records after the records' init() and constant links, before PINI
    // processing (autosave restores its values there, as synApps' pass 1).
    void set_restore_hook(std::function<void()> h) { restore_hook_ = std::move(h); }

    Record* find(std::string_view name) const; // names and aliases
    std::size_t size() const { return records_.size(); }
    std::vector<Record*> records() const; // in load order
    // Resolves "rec", "rec.FIELD", "rec.FIELD$", "rec.RTYP". Returns false with a reason if not.
    bool resolve(std::string_view channel, Address& out, std::string* why = nullptr) const;
    // True if the record part of a channel name exists (what a UDP search answers).
    bool has_record_for(std::string_view channel) const;

    // Writes n elements of type t from host-order data. With a callback, completion is reported
    // when processing ends (immediately for synchronous records); a put-callback that arrives
    // while another is active on the same record waits behind it. Returns Ok when accepted.
    PutStatus put(const Address& a, Prim t, const void* data, uint32_t n, PutCallback cb = {});
    // Who is putting, for audit logs (caPutLog's "user@host"): the CA server names its client
    // for the duration of each client put; empty when the IOC itself puts. The view is valid
    // only during that put.
    void set_put_origin(std::string_view who) { put_origin_ = who; }
    std::string_view put_origin() const { return put_origin_; }
    // dbPut: stores n elements of type t (conversion, special(), put_hook, UDF, monitors)
    // without processing the record and without the client rules of put() (autosave restore).
    PutStatus store_value(const Address& a, Prim t, const void* data, uint32_t n) {
        return store(a, t, data, n);
    }
    // Reads up to n elements as type t into dest; returns the number of valid elements.
    uint32_t get(const Address& a, Prim t, void* dest, uint32_t n) const;
    // Whether the field's value can be read as type t: a string that holds no number cannot be
    // read as a number, nor any string as an enum (EPICS's read fails: ECA_GETFAIL).
    bool readable_as(const Address& a, Prim t) const;
    // Current number of valid elements (NORD for arrays).
    uint32_t current_count(const Address& a) const;
    // Processes a record as a scan would (PROC=1).
    void process(Record& r);
    // Processes the SCAN="I/O Intr" records whose device says its value changed (the owner of
    // the devices calls it when new values arrived: an IOC after each bus snapshot).
    void scan_io_intr();
    // Processes the SCAN=Event records whose EVNT is `name`, in PHAS order (post_event).
    void post_event(std::string_view name);
    // Processes r once the current processing has ended (scanOnce; CP links use it).
    void scan_once(Record& r);
    // Calls r.on_delay() once `seconds` have passed on the clock of scan_periodic (the owner
    // calls it every 10 ms: delays have that resolution; tests drive it in virtual time), counted
    // from now on the clock set by set_clock, or else from scan_periodic's last time.
    void call_after(Record& r, double seconds, int tag = 0);
    // Offline (`beamctl db` of .db files): a hardware ("@...") address of a device DTYP is kept
    // unbound when the database has no device support for it, and a link to a record that is not
    // loaded is kept as written (softIoc would make it a CA link), instead of an error; nothing is
    // served from such a database.
    void set_offline_devices(bool on) { offline_devices_ = on; }
    // devIocStats's device supports of this database ("IOC stats", "IOC env var", "IOC epics
    // var"): its records' devices, sampled by scan_periodic (created when first asked for).
    IocStats& ioc_stats();
    // Puts r on the scan list its SCAN field now names (a record changed its own SCAN).
    void rescan(Record& r);
    // Errors of records that loaded but cannot work (Record::init_error: an SNAM no library
    // provides), "record NAME: why", in order; each is logged when it happens.
    void note_record_error(const Record& r, const std::string& why);
    const std::vector<std::string>& record_errors() const { return record_errors_; }
    // The clock scan_periodic is given (an IOC: EventLoop::now_s), so that a delay asked for
    // before the first scan counts from the right time.
    void set_clock(std::function<double()> now) { clock_ = std::move(now); }
    // That clock now (or scan_periodic's last time): what records measure time with (epid's dt).
    double now() const { return clock_ ? clock_() : now_s_; }

    // --- used by Record's link helpers and async_done() ---
    bool link_read(Record& r, Link& l, const FieldDesc& f);
    bool link_read(Record& r, Link& l, double& v);
    bool link_write(Record& r, Link& l, const FieldDesc& f);
    bool link_write(Record& r, Link& l, double v);
    void link_forward(Record& r, Link& l);
    void async_complete(Record& r, PutStatus st);

    void subscribe(Subscription& s);
    void unsubscribe(Subscription& s);
    void observe(Record& r, RecordObserver& o);
    void unobserve(Record& r, RecordObserver& o);
    // Delivers an event to the subscriptions of field f (f == nullptr: all of the record).
    void post(Record& r, const FieldDesc* f, unsigned mask);
    // Completes the active put-callback of r and starts the next queued one.
    void notify_complete(Record& r, PutStatus st);
    // Runs the put-callbacks queued on r (arrival order) while r is free: no put-callback active
    // and not busy (pact).
    void restart_waiting(Record& r);
    // The remote put an Async Soft Channel record waits for has completed (ok: without error).
    void link_put_done(Record& r, bool ok);

    // Periodic scanning: processes records whose SCAN period elapsed. `now_s` is monotonic time.
    void scan_periodic(double now_s);

    // Prints the database as .db text (fields that differ from the type's defaults).
    void write_db(std::ostream& os) const;

    const DatabaseStats& stats() const { return stats_; }

private:
    PutStatus do_put(const Address& a, Prim t, const void* data, uint32_t n, PutCallback cb);
    // Stores a value into a field (conversion, special(), put_hook, UDF, monitors); no processing.
    PutStatus store(const Address& a, Prim t, const void* data, uint32_t n);
    void apply_field(Record& rec, const DbField& f, const std::string& file);
    friend std::string link_text(const Record& r, const Link& l);
    // A link field of a record not yet initialised, set from a .db file: its text waits in
    // pending_text_ (one buffer, not a heap string per link) and is parsed again and resolved by
    // init_records, so that loading a large database leaves no freed per-link garbage between
    // its records (resident memory stays what the records use).
    void defer_link(Record& rec, const FieldDesc& fd, const DbField& f);
    Link pending_link(const Link& l, Dbf type) const; // parses the text deferred for l
    SourceLoc pending_loc(const Link& l) const;
    // dbProcess: disable check, process(), forward link, put-callback bookkeeping.
    void process_record(Record& r);
    bool disabled(Record& r);
    void resolve_links(const std::vector<Record*>& batch);
    bool resolve_link(Record& r, const FieldDesc& f, Link& l, std::string* why);
    PutStatus relink(Record& r, const FieldDesc& f, std::string_view text);
    void add_to_scan(Record& r);
    void remove_from_scan(Record& r);
    void finish_notify(PutNotify* pn);
    bool link_get(Record& r, Link& l, Prim t, void* dest, uint32_t n, uint32_t* got);
    bool link_put(Record& r, Link& l, Prim t, const void* src, uint32_t n);
    // Top-level entry points hold a Depth; the outermost one runs the scanOnce queue at its end.
    struct Depth {
        Database& db;
        explicit Depth(Database& d) : db(d) { ++db.depth_; }
        ~Depth();
    };

    struct Hash {
        using is_transparent = void;
        std::size_t operator()(std::string_view s) const { return std::hash<std::string_view>{}(s); }
    };
    RecordIndex records_; // by name; the records are owned through order_ (deleted by remove and ~Database)
    std::unordered_map<std::string, Record*, Hash, std::equal_to<>> aliases_;
    std::vector<Record*> order_;
    std::vector<Record*> uninitialised_;
    struct ScanList {
        double period_s;
        double next_s = 0;
        std::vector<Record*> recs;
    };
    std::vector<ScanList> scans_;
    struct Poll {
        Record* rec;
        double next_s;
        int tag = 0; // call_after's tag (Record::on_delay(tag))
    };
    std::vector<Poll> polls_; // records that poll their device (Record::poll_period_s)
    std::vector<Poll> delays_; // call_after: (record, when)
    std::vector<std::string> record_errors_;
    // Where each record not yet initialised was defined (init errors say it), until init_records.
    struct RecordLoc {
        uint32_t file;
        int line, col;
    };
    std::unordered_map<const Record*, RecordLoc> record_locs_;
    std::vector<std::string> record_loc_files_;
    bool offline_devices_ = false;
    std::unique_ptr<IocStats> ioc_stats_;
    struct IoIntr {
        Record* rec;
        std::vector<LinkDevice*> devices; // of its links, found when io_intr_stale_ is set
        LinkDevice* readback = nullptr;   // an output record's OUT device: VAL follows it (asyn)
        bool passive = false;             // info(asyn:READBACK, "1") on a non-I/O Intr output: VAL
                                          // follows the device without processing (no write back)
    };
    std::vector<IoIntr> io_intr_; // SCAN "I/O Intr" records (all have a bound device link), read-backs
    bool io_intr_stale_ = true;    // a link of one of them may have changed (relink, add)
    double now_s_ = 0;         // the last time scan_periodic was given
    std::string_view put_origin_; // set_put_origin
    std::function<double()> clock_;
    std::unordered_map<std::string, std::vector<Record*>> events_; // SCAN=Event by EVNT, PHAS order
    std::deque<Record*> once_;                                       // scanOnce queue
    int depth_ = 0;
    PutNotify* notify_ = nullptr; // the put-callback the processing in progress belongs to
    std::vector<std::unique_ptr<class CpLinkWatch>> cp_watches_;
    LinkBinder binder_;
    RemoteBinder remote_binder_;
    std::function<void()> restore_hook_; // set_restore_hook
    struct PendingLink {
        uint32_t offset, size; // in pending_text_
        uint32_t file;         // in pending_files_
        int line, col;
    };
    std::string pending_text_;
    std::vector<PendingLink> pending_links_;
    std::vector<std::string> pending_files_;
    DatabaseStats stats_;
};

} // namespace beamctl::pv
