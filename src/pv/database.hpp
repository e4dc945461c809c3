// The process-variable database: records by name, channel addresses ("rec.FIELD$"), puts with
// completion callbacks applied in arrival order, gets with conversion, monitors, .db import/export.
// Threading: one thread owns a Database (the IOC loop); other threads hand work to that thread.
#pragma once

#include "pv/db_file.hpp"
#include "pv/record.hpp"

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
    enum class Kind : uint8_t { Field, LongString, RecordType };
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

struct DatabaseStats {
    uint64_t puts = 0, gets = 0, posts = 0, processes = 0, bad_puts = 0;
};

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
    // Runs init() of records not yet initialised and processes those with PINI=YES.
    void init_records();

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
    // Reads up to n elements as type t into dest; returns the number of valid elements.
    uint32_t get(const Address& a, Prim t, void* dest, uint32_t n) const;
    // Current number of valid elements (NORD for arrays).
    uint32_t current_count(const Address& a) const;
    // Processes a record as a scan would (PROC=1).
    void process(Record& r);

    void subscribe(Subscription& s);
    void unsubscribe(Subscription& s);
    void observe(Record& r, RecordObserver& o);
    void unobserve(Record& r, RecordObserver& o);
    // Delivers an event to the subscriptions of field f (f == nullptr: all of the record).
    void post(Record& r, const FieldDesc* f, unsigned mask);
    // Completes the active put-callback of r and starts the next queued one.
    void notify_complete(Record& r, PutStatus st);

    // Periodic scanning: processes records whose SCAN period elapsed. `now_s` is monotonic time.
    void scan_periodic(double now_s);

    // Prints the database as .db text (fields that differ from the type's defaults).
    void write_db(std::ostream& os) const;

    const DatabaseStats& stats() const { return stats_; }

private:
    PutStatus do_put(const Address& a, Prim t, const void* data, uint32_t n, PutCallback cb);
    void apply_field(Record& rec, const DbField& f, const std::string& file);

    struct Hash {
        using is_transparent = void;
        std::size_t operator()(std::string_view s) const { return std::hash<std::string_view>{}(s); }
    };
    std::unordered_map<std::string, std::unique_ptr<Record>, Hash, std::equal_to<>> records_;
    std::unordered_map<std::string, Record*, Hash, std::equal_to<>> aliases_;
    std::vector<Record*> order_;
    std::vector<Record*> uninitialised_;
    struct ScanList {
        double period_s;
        double next_s = 0;
        std::vector<Record*> recs;
    };
    std::vector<ScanList> scans_;
    DatabaseStats stats_;
};

} // namespace beamctl::pv
