// Record links (EPICS dbLink): the INP/OUT/DOL/FLNK/... fields of records. A link is parsed from
// its text when a .db file sets it, resolved to its target once all records are loaded
// (Database::resolve_links, at init), and used by record processing through Record::read_link,
// Record::write_link and the database's forward-link processing.
//
// Text forms (as EPICS base 7 dbParseLink):
//   ""                         empty: nothing is read or written
//   "1.5", "0x10", "-3"        constant: loaded into the record once at init (Record::load_constant)
//   {const: 1.5} {const:"s"}   JSON constant; {const: [1, 2]} an array constant
//   "rec", "rec.FIELD"         database link to a field of a record in this database (VAL if none),
//                              followed by modifiers: NPP PP CA CP CPP (process) and NMS MS MSS MSI
//                              (alarm propagation), blank- or comma-separated
//   "@text"                    hardware address for the record's device support (DTYP)
// A "rec..." link with CA, CP or CPP whose record is not in this database is a Channel Access
// link (RemoteLink) when the database has a remote binder; without CA/CP/CPP it is a load error.
// Threading: links belong to their record and are used on the database thread only.
#pragma once

#include "core/error.hpp"
#include "pv/types.hpp"

#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::pv {

class Record;
struct FieldDesc;

// Device support of a hardware ("@...") link: bound by whoever owns the address (an IOC binds
// "@ec0.s3.positionActual01" to its signal). Methods run on the database thread.
class LinkDevice {
public:
    virtual ~LinkDevice() = default;
    virtual bool read(double& v) = 0;        // false: no value (the record raises read_alarm()/INVALID)
    // The alarm status a failed read raises: LINK (default), or COMM for a device whose hardware
    // does not answer (an EtherCAT slave missing or lost).
    virtual uint16_t read_alarm() const { return kStatLink; }
    virtual bool write(double v) = 0;        // false: refused (the record raises LINK/INVALID)
    // A device whose value is text (devIocStats's stringin and waveform parameters): records read
    // it with read_text (a string, or a CHAR array); false raises read_alarm() with `out` as value.
    virtual bool is_text() const { return false; }
    virtual bool read_text(std::string& out) { (void)out; return false; }
    virtual std::string describe() const = 0; // for dbpr/introspection
    // SCAN "I/O Intr": true when the value differs from the one the record last read.
    virtual bool changed() { return false; }
    // The link was replaced (a put to INP/OUT) or its record removed: give back what binding took
    // (an output's one-writer claim). No more calls follow.
    virtual void release() {}
};

// A Channel Access link to a record of another server (EPICS dbCa): made by the database's
// remote binder (Database::set_remote_binder) for an INP/OUT/DOL/FLNK link with CA, CP or CPP
// whose record is not in this database, and kept in Link::device of that Db link (whose target
// stays null). Methods run on the database thread.
class RemoteLink : public LinkDevice {
public:
    struct Value {
        Prim type = Prim::Double;
        uint32_t count = 0;
        const void* data = nullptr; // count elements in host order (a string is char[40])
        uint16_t stat = 0, sevr = 0;
        EpicsTime time;
        const char* enum_string = nullptr; // an enum's state string (char[40]) when known
    };
    // The last value the link's monitor received; false while disconnected or before the first.
    virtual bool value(Value& out) const = 0;
    // Writes n elements of type t without waiting (WRITE); false while disconnected or read-only.
    virtual bool put(Prim t, const void* data, uint32_t n) = 0;
    // Writes with completion (WRITE_NOTIFY, dbCaPutLinkCallback): done(true) once the remote
    // processing completed, done(false) on an error or a disconnection; returns false (and never
    // calls done) while disconnected or read-only. done runs on the database thread.
    virtual bool put_notify(Prim t, const void* data, uint32_t n, std::function<void(bool ok)> done) = 0;
    virtual bool connected() const = 0;
    // The remote field's native type once known (Double before).
    virtual Prim type() const = 0;
    // The link was replaced or its record removed: no more callbacks into the database.
    void release() override = 0;
    // LinkDevice, for code that sees any device: a scalar double in and out.
    bool read(double&) override { return false; }
    bool write(double v) override { return put(Prim::Double, &v, 1); }
};

// What a link was written as, where, and its parts. A link keeps it while it needs it: a database
// link to a record of this database drops it once resolved (its text is rebuilt from the target),
// so that the thousands of links of a large database cost little memory; constants, hardware
// addresses and CA links keep it.
struct LinkSpec {
    std::string text; // as written (what clients read)
    SourceLoc loc;    // where the .db file set it (for load errors)
    // Constant
    std::vector<double> numbers; // numeric constant(s)
    std::string string_constant; // {const: "text"}
    bool is_string_constant = false;
    // Db: "rec.FIELD" as written
    std::string record, field;
    // Hw: the address after '@'
    std::string address;
};

// The heap part of a set link: what it resolved to and, while needed, what it was written as.
struct LinkState {
    // resolved at init: the target of a Db link, the device of a Hw (or CA) link
    Record* target = nullptr;
    const FieldDesc* target_field = nullptr;
    LinkDevice* device = nullptr;
    std::unique_ptr<LinkSpec> spec; // null once a Db link resolved into this database
    bool field_written = false;     // a resolved Db link was written "rec.FIELD", not "rec"
};

struct Link {
    enum class Kind : uint8_t { Empty, Constant, Db, Hw };
    enum Proc : uint8_t { kNpp, kPp, kCa, kCp, kCpp };
    enum Ms : uint8_t { kNms, kMs, kMss, kMsi };

    Kind kind = Kind::Empty;
    uint8_t proc = kNpp;
    uint8_t ms = kNms;
    // Set while the link's text waits in its Database until init_records parses and resolves it
    // (Database::load keeps load-time link text out of the heap between records): the index + 1
    // of that text. Kind and modifiers are already set; state is null until then.
    uint32_t pending = 0;
    // What the link resolved to and was written as; null while the link is empty (most of a
    // record's link fields: 16 bytes each then).
    std::unique_ptr<LinkState> state;

    // Resolved at init: the target of a Db link, the device of a Hw link (null when empty).
    Record* target() const { return state ? state->target : nullptr; }
    const FieldDesc* target_field() const { return state ? state->target_field : nullptr; }
    LinkDevice* device() const { return state ? state->device : nullptr; }
    // Sets them (an empty link has nothing to set: a no-op).
    void set_target(Record* r, const FieldDesc* f) {
        if (state) state->target = r, state->target_field = f;
    }
    void set_device(LinkDevice* d) {
        if (state) state->device = d;
    }
    // A Db link resolved into this database no longer needs its text: drop it (it is rebuilt from
    // the target when asked for). Keeps it when the target field differs from the one written
    // (a forward link to "rec.X" processes rec).
    void forget_spec();
    // Rebuilds the spec of a resolved Db link from its target (before the target goes away or the
    // link is resolved again).
    void restore_spec();

    // The link as written (an empty spec for an empty link and for a resolved Db link: use
    // record_name()/field_name()/canonical() for those).
    const LinkSpec& s() const {
        static const LinkSpec empty_spec;
        return state && state->spec ? *state->spec : empty_spec;
    }
    // A Db link's record and field as written (the field empty for "rec").
    std::string_view record_name() const;
    std::string_view field_name() const;
    bool empty() const { return kind == Kind::Empty; }
    bool is_constant() const { return kind == Kind::Constant; }
    bool is_db() const { return kind == Kind::Db; }
    // The CA link of a Db link to another server (nullptr for any other link).
    RemoteLink* remote() const {
        return kind == Kind::Db && state && !state->target && state->device ? static_cast<RemoteLink*>(state->device)
                                                                            : nullptr;
    }
    // Link text with its modifiers as EPICS prints them ("rec.VAL PP MS").
    std::string canonical() const;
};

// Parses link text into `out` (not resolved). On a syntax error returns false with *why.
bool parse_link(std::string_view text, Dbf kind, Link& out, std::string* why);

const char* link_proc_name(uint8_t proc);
const char* link_ms_name(uint8_t ms);

} // namespace beamctl::pv
