#include "pv/database.hpp"

#include "core/error.hpp"
#include "core/error_list.hpp"
#include "core/log.hpp"
#include "pv/convert.hpp"
#include "pv/ioc_stats.hpp"

#include <algorithm>
#include <malloc.h>
#include <cstdio>
#include <cstring>

namespace beamctl::pv {

// A CP/CPP input link: a monitor on the target field that processes the link's record (through
// the scanOnce queue, after the processing that posted the change has ended).
class CpLinkWatch : public Subscription {
public:
    CpLinkWatch(Database& db, Record& src, const FieldDesc& src_field, bool cpp)
        : db_(db), src_(src), src_field_(src_field), cpp_(cpp) {}
    void on_event(unsigned) override {
        if (cpp_ && src_.scan != 0) return; // CPP: only a Passive record
        db_.scan_once(src_);
    }
    Record& src() const { return src_; }
    const FieldDesc& src_field() const { return src_field_; }

private:
    Database& db_;
    Record& src_;
    const FieldDesc& src_field_;
    bool cpp_;
};

Database::Depth::~Depth() {
    if (--db.depth_ > 0 || db.once_.empty()) return;
    ++db.depth_;
    // Bounded: a CP loop (A -> B -> A) must not hang the caller; the rest runs at the next call.
    for (int k = 0; k < 100000 && !db.once_.empty(); ++k) {
        Record* r = db.once_.front();
        db.once_.pop_front();
        db.process_record(*r);
    }
    --db.depth_;
}

bool Address::writable() const {
    if (kind == Kind::RecordType || !field) return false;
    if (rec->val_read_only && field->name[0] == 'V' && std::strcmp(field->name, "VAL") == 0) return false;
    return !(field->flags & (kReadOnly | kInitOnly));
}

int Address::asl() const { return field && (field->flags & kAsl0) ? 0 : 1; }

Database::Database() = default;

Database::~Database() {
    for (auto& w : cp_watches_) unsubscribe(*w);
    cp_watches_.clear();
    for (auto* r : order_) r->db_ = nullptr;
    for (auto* r : order_) delete r;
}

IocStats& Database::ioc_stats() {
    if (!ioc_stats_) ioc_stats_ = std::make_unique<IocStats>();
    return *ioc_stats_;
}

namespace {
log::Logger lg("pv.db");
bool is_val(const FieldDesc& f) { return f.name[0] == 'V' && f.name[1] == 'A' && f.name[2] == 'L' && !f.name[3]; }
bool is_named(const FieldDesc& f, const char* n) { return std::strcmp(f.name, n) == 0; }

// A double seen as a field, for converting link values that are not in a record.
const FieldDesc kScratchDouble{"", Dbf::Double, 0, 8, nullptr, nullptr};
const FieldDesc kScratchString{"", Dbf::String, 0, kStringSize, nullptr, nullptr}; // a number's text: precision 6

// The CA type a value travels in between two fields (dbFastLinkConv keeps strings and enums).
Prim transfer_prim(Dbf to, Dbf from) {
    if (to == Dbf::String || from == Dbf::String) return Prim::String;
    if ((to == Dbf::Enum || to == Dbf::Menu) && (from == Dbf::Enum || from == Dbf::Menu)) return Prim::Enum;
    return Prim::Double;
}

// "Async Soft Channel" (devSoftCallback) of a record whose DTYP is base's soft menu.
bool async_soft(const Record& r) {
    const FieldDesc* f = r.type().find("DTYP");
    return r.dtyp == kDtypAsyncSoft && f && f->menu == &kMenuSoftDtyp;
}

// A link to a long string (lsi VAL) carries it whole to a char array, one string to the rest.
void as_string_head(Address& a, Prim t, uint32_t n) {
    if (!(a.field->flags & kLongString) || (t == Prim::Char && n > 1)) return;
    a.kind = Address::Kind::StringHead;
    a.native = Prim::String;
    a.count = 1;
}

// The type a link's value comes in: its target field's, a CA link's remote native type.
Dbf source_dbf(const Link& l) {
    if (l.target_field()) return (l.target_field()->flags & kLongString) ? Dbf::String : l.target_field()->dbf;
    if (l.kind == Link::Kind::Hw && l.device() && l.device()->is_text()) return Dbf::String;
    if (RemoteLink* rl = l.remote()) {
        switch (rl->type()) {
        case Prim::String: return Dbf::String;
        case Prim::Enum: return Dbf::Enum;
        default: return Dbf::Double;
        }
    }
    return Dbf::Double;
}

// A value of CA type p seen as a field, for converting what a CA link received (an enum as its
// index: the states are the other server's).
const FieldDesc& scratch_field(Prim p) {
    static const FieldDesc fields[] = {
        {"", Dbf::String, 0, kStringSize, nullptr, nullptr}, {"", Dbf::Short, 0, 2, nullptr, nullptr},
        {"", Dbf::Float, 0, 4, nullptr, nullptr},            {"", Dbf::UShort, 0, 2, nullptr, nullptr},
        {"", Dbf::UChar, 0, 1, nullptr, nullptr},            {"", Dbf::Long, 0, 4, nullptr, nullptr},
        {"", Dbf::Double, 0, 8, nullptr, nullptr}};
    return fields[int(p) <= 6 ? int(p) : 6];
}

double scan_period(uint16_t scan) {
    static const double periods[] = {0, 0, 0, 10, 5, 2, 1, 0.5, 0.2, 0.1};
    return scan < 10 ? periods[scan] : 0;
}
} // namespace

// Record types of EPICS base and the common synApps modules that beamctl does not serve (yet):
// a database that uses one is told "not supported", not "unknown".
static bool known_epics_type(std::string_view t) {
    static const char* known[] = {"swait", "sseq", "scalcout", "acalcout",
                                  "transform", "scaler", "asyn", "timestamp",
                                  "digitel", "table", "sCalcout", "vs", "pid", "steppermotor"};
    for (const char* k : known)
        if (t == k) return true;
    return false;
}

// Fields of EPICS base's standard record types that beamctl's records do not implement.
static bool known_epics_field(std::string_view f) {
    static const char* known[] = {
        "UTAG", "SIML", "SIOL", "SIMS", "SIMM", "SSCN", "SDLY", "OLDSIMM", "LINR",
        "EGUF", "EGUL", "AOFF", "ASLO", "ESLO", "EOFF", "ROFF", "RVAL", "ORAW", "ORBV", "RBV",
        "INIT", "LBRK", "OMOD", "SVAL", "IVOA", "IVOV", "OROC",
        "AFTC", "AFVL", "MPST", "APST", "HASH", "BUSY", "NORD", "BPTR", "RARM", "OLDN", "WAIT", "OUTV",
        "CLCV", "OCLV", "INAV", "INBV", "INCV", "INDV", "INEV", "INFV", "INGV", "INHV", "INIV",
        "INJV", "INKV", "INLV", "DLYA", "TPRO", "OOPT", "OOCH", "NLST", "HIGH", "AMSG", "NAMSG"};
    for (const char* k : known)
        if (f == k) return true;
    return false;
}

// Fields of base's records that are DBF_NOACCESS (pointers and private state): no database may set
// them (base's dbPutString refuses them too).
static bool noaccess_epics_field(std::string_view f) {
    static const char* noaccess[] = {"ASP", "BKPT", "MLOK", "MLIS", "PPN", "PPNR", "SPVT", "RSET", "DSET",
                                     "DPVT", "RDES", "LSET", "TIME", "SIMPVT", "PBRK", "RPVT", "WDPT",
                                     "WDOG", "EPVT", "RPCL", "ORPC", "BPTR", "CVT", "PVT", "SADR",
                                     "CBAK", "BKLNK", "priv"};
    for (const char* k : noaccess)
        if (f == k) return true;
    return false;
}

void Database::apply_field(Record& rec, const DbField& f, const std::string& file) {
    (void)file;
    const FieldDesc* fd = rec.type().find(f.name);
    if (!fd && noaccess_epics_field(f.name))
        throw Error(SB() << f.loc.str() << ": field " << f.name << " of record " << rec.name()
                         << " is DBF_NOACCESS: no database may set it (as in EPICS base)");
    if (!fd && known_epics_field(f.name))
        throw Error(SB() << f.loc.str() << ": field " << f.name << " of record type " << rec.type().name()
                         << " is not supported by beamctl (record " << rec.name() << ")");
    if (!fd)
        throw Error(SB() << f.loc.str() << ": record type " << rec.type().name() << " has no field "
                         << f.name << " (record " << rec.name() << ")");
    // A read-only field (SPC_NOMOD) is set from a file as base's dbPutString sets it (no check of
    // `special`); clients and dbpf still cannot write it. RTYP is no field of base's static database.
    if ((fd->flags & kReadOnly) && f.name == "RTYP")
        throw Error(SB() << f.loc.str() << ": record " << rec.name() << ": RTYP is the record type, not a field a database sets");
    if (fd->flags & kArray)
        throw Error(SB() << f.loc.str() << ": field " << f.name << " of record " << rec.name()
                         << " is an array; initial array values are not supported");
    if (is_link(fd->dbf) && !rec.initialised_) return defer_link(rec, *fd, f);
    std::string err;
    if (!parse_field(rec, *fd, f.value, &err))
        throw Error(SB() << f.loc.str() << ": record " << rec.name() << ": " << err);
    if (fd->menu == &kMenuSoftDtyp)
        if (const char* why = dtyp_refusal(rec.type().name(), rec.dtyp))
            throw Error(SB() << f.loc.str() << ": record " << rec.name() << ": DTYP \"" << f.value
                             << "\": record type " << rec.type().name() << " " << why);
    if (is_link(fd->dbf))
        if (auto& st = field_ref<Link>(rec, *fd).state; st && st->spec) st->spec->loc = f.loc;
    if (is_val(*fd)) rec.udf = 0; // a VAL given in the file defines the value
}

void Database::defer_link(Record& rec, const FieldDesc& fd, const DbField& f) {
    Link probe; // syntax errors are load errors, with the field's file:line:col
    std::string why;
    if (!parse_link(f.value, fd.dbf, probe, &why))
        throw Error(SB() << f.loc.str() << ": record " << rec.name() << ": field " << fd.name << ": " << why);
    Link& l = field_ref<Link>(rec, fd);
    l = Link{};
    l.kind = probe.kind;
    l.proc = probe.proc;
    l.ms = probe.ms;
    if (probe.kind == Link::Kind::Empty) return;
    if (pending_files_.empty() || pending_files_.back() != f.loc.file) pending_files_.push_back(f.loc.file);
    pending_links_.push_back({uint32_t(pending_text_.size()), uint32_t(f.value.size()),
                              uint32_t(pending_files_.size() - 1), f.loc.line, f.loc.col});
    pending_text_ += f.value;
    l.pending = uint32_t(pending_links_.size());
}

Link Database::pending_link(const Link& l, Dbf type) const {
    Link fresh;
    const PendingLink& p = pending_links_.at(l.pending - 1);
    if (!parse_link(std::string_view(pending_text_).substr(p.offset, p.size), type, fresh, nullptr))
        throw Error("internal: a deferred link no longer parses"); // it parsed when deferred
    return fresh;
}

SourceLoc Database::pending_loc(const Link& l) const {
    const PendingLink& p = pending_links_.at(l.pending - 1);
    return SourceLoc{pending_files_[p.file], p.line, p.col};
}

std::string link_text(const Record& r, const Link& l) {
    if (l.pending && !l.state) // still waiting for init_records (read before iocInit)
        return r.database() ? r.database()->pending_link(l, Dbf::InLink).canonical() : std::string();
    return l.canonical();
}

void Database::load(const DbFile& file, const RecordTypes& types) {
    // Validate and build everything first, so a file with an error adds nothing; every error of
    // the file is reported (each field of each record), not the first only.
    struct Pending {
        std::unique_ptr<Record> fresh; // new record, or null when merging into an existing one
        Record* rec;
    };
    ErrorList errs;
    std::vector<Pending> todo;
    std::unordered_map<std::string, Record*> created;
    for (const DbRecord& dr : file.records) {
        Record* existing = find(dr.name);
        if (!existing) {
            auto it = created.find(dr.name);
            if (it != created.end()) existing = it->second;
        }
        if (existing) {
            if (dr.type != "*" && dr.type != existing->type().name()) {
                errs.add(SB() << dr.loc.str() << ": record " << dr.name << " already exists with type "
                              << existing->type().name() << ", not " << dr.type);
                continue;
            }
            for (const DbField& f : dr.fields) errs.capture([&] { apply_field(*existing, f, dr.loc.file); });
            continue;
        }
        if (dr.type == "*") {
            errs.add(SB() << dr.loc.str() << ": record(\"*\", \"" << dr.name << "\") modifies a record that does not exist");
            continue;
        }
        const RecordType* t = types.find(dr.type);
        if (!t) {
            SB sb;
            if (known_epics_type(dr.type))
                sb << dr.loc.str() << ": record type '" << dr.type << "' is not supported by beamctl yet (supported:";
            else
                sb << dr.loc.str() << ": unknown record type '" << dr.type << "' (supported:";
            for (auto& n : types.names()) sb << " " << n;
            sb << ")";
            errs.add(sb);
            continue;
        }
        if (dr.name.empty() || dr.name.size() > 60) {
            errs.add(SB() << dr.loc.str() << ": record name '" << dr.name << "' must have 1 to 60 characters");
            continue;
        }
        bool bad_name = false;
        for (char c : dr.name)
            if (c == '.' || c == ' ' || c == '"' || c == '\'' || c == '$' || c == '{' || c == '}') {
                errs.add(SB() << dr.loc.str() << ": record name '" << dr.name << "' contains the character '" << c
                              << "'");
                bad_name = true;
                break;
            }
        if (bad_name) continue;
        auto rec = t->create();
        copy_string(rec->name_, sizeof rec->name_, dr.name);
        bool ok = true;
        for (const DbField& f : dr.fields) ok &= errs.capture([&] { apply_field(*rec, f, dr.loc.file); });
        if (!ok) continue;
        for (const DbInfo& i : dr.infos) rec->info_.emplace_back(i.name, i.value);
        for (const std::string& a : dr.aliases) rec->aliases_.push_back(a);
        created[dr.name] = rec.get();
        Record* raw = rec.get();
        todo.push_back({std::move(rec), raw});
        if (record_loc_files_.empty() || record_loc_files_.back() != dr.loc.file) record_loc_files_.push_back(dr.loc.file);
        record_locs_[raw] = {uint32_t(record_loc_files_.size() - 1), dr.loc.line, dr.loc.col};
    }
    for (const DbAlias& a : file.aliases) {
        if (!find(a.record) && !created.count(a.record))
            errs.add(SB() << a.loc.str() << ": alias '" << a.alias << "' names record '" << a.record
                          << "' which does not exist");
    }
    for (auto& p : todo) {
        for (auto& a : p.rec->aliases_)
            if (find(a) || created.count(a))
                errs.add(SB() << "alias '" << a << "' of record " << p.rec->name() << " clashes with an existing name");
    }
    for (const DbAlias& a : file.aliases)
        if (find(a.alias) || created.count(a.alias))
            errs.add(SB() << a.loc.str() << ": alias '" << a.alias << "' already exists");
    errs.throw_if_any();
    for (auto& p : todo) add(std::move(p.fresh));
    for (auto& p : todo)
        for (auto& a : p.rec->aliases_) aliases_[a] = p.rec;
    for (const DbAlias& a : file.aliases) {
        Record* r = find(a.record);
        aliases_[a.alias] = r;
        r->aliases_.push_back(a.alias);
    }
}

Record& Database::add(std::unique_ptr<Record> rec) {
    std::string name(rec->name());
    if (find(name)) throw Error(SB() << "record " << name << " already exists");
    rec->db_ = this;
    Record* raw = rec.release(); // owned through order_
    records_.insert(raw);
    order_.push_back(raw);
    uninitialised_.push_back(raw);
    return *raw;
}

void Database::add_alias(std::string_view record, std::string_view alias) {
    Record* r = find(record);
    if (!r) throw Error(SB() << "alias " << alias << ": no record " << record);
    if (find(alias)) throw Error(SB() << "alias " << alias << " already exists");
    aliases_[std::string(alias)] = r;
    r->aliases_.emplace_back(alias);
}

void Database::remove(std::string_view name) {
    Record* r = records_.find(name);
    if (!r) return;
    auto observers = r->observers_; // observers unregister themselves while being told
    for (auto* o : observers) o->on_record_removed(*r);
    r->subs_.clear();
    if (r->notify_) {
        if (r->notify_->active) r->notify_->active(PutStatus::Disconnected);
        for (auto& q : r->notify_->queue) q.cb(PutStatus::Disconnected);
        r->notify_.reset();
    }
    for (auto a = aliases_.begin(); a != aliases_.end();)
        a = a->second == r ? aliases_.erase(a) : std::next(a);
    order_.erase(std::remove(order_.begin(), order_.end(), r), order_.end());
    uninitialised_.erase(std::remove(uninitialised_.begin(), uninitialised_.end(), r),
                         uninitialised_.end());
    remove_from_scan(*r);
    polls_.erase(std::remove_if(polls_.begin(), polls_.end(), [&](const Poll& p) { return p.rec == r; }), polls_.end());
    delays_.erase(std::remove_if(delays_.begin(), delays_.end(), [&](const Poll& p) { return p.rec == r; }), delays_.end());
    once_.erase(std::remove(once_.begin(), once_.end(), r), once_.end());
    // CP watches from or onto r; links of other records onto r become broken (LINK alarm).
    for (auto w = cp_watches_.begin(); w != cp_watches_.end();) {
        if (&(*w)->src() == r || (*w)->addr.rec == r) {
            unsubscribe(**w);
            w = cp_watches_.erase(w);
        } else {
            ++w;
        }
    }
    for (const FieldDesc& f : r->type().fields()) // its CA links stop, its devices give back outputs
        if (is_link(f.dbf)) {
            Link& l = field_ref<Link>(*r, f);
            if (RemoteLink* rl = l.remote()) rl->release();
            else if (l.kind == Link::Kind::Hw && l.device()) l.device()->release();
        }
    if (r->pn_ && --r->pn_->pending == 0 && r->pn_->started) finish_notify(r->pn_);
    for (Record* o : order_) {
        if (o->pn_ && o->pn_->origin == r) o->pn_->origin = nullptr;
        for (const FieldDesc& f : o->type().fields())
            if (is_link(f.dbf)) {
                Link& l = field_ref<Link>(*o, f);
                if (l.target() == r) {
                    l.restore_spec(); // the text stays what it was
                    l.set_target(nullptr, nullptr);
                }
            }
    }
    records_.erase(r->name());
    delete r;
}

void Database::init_records() {
    std::vector<Record*> batch;
    batch.swap(uninitialised_);
    // The parsed files are freed by now, as small chunks the allocator keeps apart (fast bins);
    // what init allocates next (a link's state, a compiled CALC) would land in them scattered
    // over that whole region and keep it resident. Merged and given back first, the new
    // allocations are carved in order from one free region instead (glibc malloc_trim).
    if (batch.size() >= 1000) ::malloc_trim(0);
    try {
        resolve_links(batch);
    } catch (...) {
        uninitialised_.swap(batch);
        throw;
    }
    ErrorList init_errors; // every record's, each with where the record was defined
    for (Record* r : batch) {
        // iocInit's doInitRecord0, before init_record: a record the file left undefined starts
        // with severity UDFS; one whose VAL the file set starts without alarm, its status still
        // UDF until processed. A constant link loaded by init() does not change this (as base).
        if (r->stat == kStatUdf) r->sevr = r->udf ? r->udfs : uint16_t(kNoAlarm);
        try {
            r->init();
        } catch (const Error& e) {
            std::string msg = SB() << "record " << r->name() << ": " << e.what();
            auto at = record_locs_.find(r);
            if (at != record_locs_.end())
                init_errors.add(SourceLoc{record_loc_files_[at->second.file], at->second.line, at->second.col}, msg);
            else
                init_errors.add(msg);
            continue;
        }
        r->initialised_ = true;
        add_to_scan(*r);
        if (r->poll_period_s() > 0) polls_.push_back({r, 0});
    }
    std::unordered_map<const Record*, RecordLoc>().swap(record_locs_);
    std::vector<std::string>().swap(record_loc_files_);
    init_errors.throw_if_any();
    if (ioc_stats_) ioc_stats_->set_record_count(records_.size());
    if (restore_hook_ && !batch.empty()) restore_hook_(); // autosave: after init, before PINI
    // PINI: YES, then RUN and RUNNING (this IOC runs as soon as it is initialised), each in PHAS
    // order (stable: load order within a phase), as iocInit's piniProcess.
    Depth d(*this);
    for (uint16_t when : {uint16_t(1), uint16_t(2)}) {
        std::vector<Record*> pini;
        for (Record* r : batch)
            if ((when == 1 && r->pini == 1) || (when == 2 && (r->pini == 2 || r->pini == 3))) pini.push_back(r);
        std::stable_sort(pini.begin(), pini.end(), [](Record* x, Record* y) { return x->phas < y->phas; });
        for (Record* r : pini) process_record(*r);
    }
    // A CP link processes its record once at start, as the first monitor update of EPICS's CA
    // link does (after the PINI records).
    for (auto& w : cp_watches_)
        if (std::find(batch.begin(), batch.end(), &w->src()) != batch.end()) w->on_event(kDbeValue);
}

void Database::resolve_links(const std::vector<Record*>& batch) {
    ErrorList errs;
    std::vector<Record*> bad;
    for (Record* r : batch)
        for (const FieldDesc& f : r->type().fields()) {
            if (!is_link(f.dbf)) continue;
            Link& l = field_ref<Link>(*r, f);
            Link deferred;
            if (l.pending) { // its text waited here since load: parse it now, in resolution order
                deferred.pending = l.pending;
                l = pending_link(l, f.dbf);
            }
            std::string why;
            if (resolve_link(*r, f, l, &why)) continue;
            bad.push_back(r);
            std::string msg = SB() << "record " << r->name() << " field " << f.name << " \"" << l.s().text << "\": " << why;
            SourceLoc loc = deferred.pending ? pending_loc(deferred) : l.s().loc;
            if (!loc.file.empty()) errs.add(loc, msg);
            else errs.add(msg);
        }
    // every deferred link of the batch is parsed now (the batch is all records not initialised)
    std::string().swap(pending_text_);
    std::vector<PendingLink>().swap(pending_links_);
    std::vector<std::string>().swap(pending_files_);
    for (Record* r : batch) {
        if (r->scan != 2 || std::find(bad.begin(), bad.end(), r) != bad.end()) continue;
        bool device = false;
        for (const FieldDesc& f : r->type().fields())
            if (is_link(f.dbf) && field_ref<Link>(*r, f).kind == Link::Kind::Hw &&
                (field_ref<Link>(*r, f).device() || (offline_devices_ && !soft_dtyp(r->dtyp))))
                device = true;
        if (!device)
            errs.add(SB() << "record " << r->name() << ": SCAN \"I/O Intr\" needs device support with "
                             "interrupts (DTYP \"beamctl\" and an \"@signal\" link); Soft Channel has none "
                             "(use Passive with a CP input link, Event or a period)");
    }
    errs.throw_if_any();
}

bool Database::resolve_link(Record& r, const FieldDesc& f, Link& l, std::string* why) {
    auto fail = [&](std::string m) {
        if (why) *why = std::move(m);
        return false;
    };
    l.restore_spec(); // resolved before: its text was rebuilt from the target
    l.set_target(nullptr, nullptr);
    l.set_device(nullptr);
    switch (l.kind) {
    case Link::Kind::Empty:
    case Link::Kind::Constant: return true;
    case Link::Kind::Hw: {
        const FieldDesc* dtyp_fd = r.type().find("DTYP");
        bool soft_menu = dtyp_fd && dtyp_fd->menu == &kMenuSoftDtyp;
        if (soft_menu && (r.dtyp == kDtypTimestamp || r.dtyp == kDtypGetenv || r.dtyp == kDtypStdio))
            return true; // INST_IO soft device support: the record reads the text itself
        if (soft_menu && ioc_stats_dtyp(r.dtyp)) { // devIocStats: this database's own devices
            LinkDevice* d = ioc_stats().bind(r, l, r.dtyp, why);
            if (!d) return false;
            l.set_device(d);
            return true;
        }
        if (soft_menu && soft_dtyp(r.dtyp))
            return fail(SB() << "the hardware address '@" << l.s().address << "' needs DTYP \"beamctl\" (DTYP \""
                             << kMenuSoftDtyp.choices[r.dtyp] << "\" has no hardware)");
        if (!binder_ && offline_devices_) return true; // kept as written, bound by no one
        if (!binder_)
            return fail(SB() << "the hardware address '@" << l.s().address
                             << "' needs device support (DTYP), and this database has none");
        LinkDevice* d = binder_(r, f, l, why);
        if (!d) return false;
        l.set_device(d);
        return true;
    }
    case Link::Kind::Db: break;
    }
    const LinkSpec& spec = l.s();
    Record* t = find(spec.record);
    if (!t && offline_devices_) return true; // offline: another file's (or IOC's) record, kept as written
    if (!t) {
        if (l.proc != Link::kCa && l.proc != Link::kCp && l.proc != Link::kCpp)
            return fail(SB() << "no record '" << spec.record << "' (a link to another server needs the CA modifier)");
        if (!remote_binder_)
            return fail(SB() << "no record '" << spec.record
                             << "' here, and this database has no Channel Access client for links to other servers");
        if (f.dbf == Dbf::FwdLink && spec.field != "PROC") // dbCa writes 1 to the PROC it names
            return fail(SB() << "no record '" << spec.record << "' here; a forward link to another server must name "
                             << "its PROC field (\"" << spec.record << ".PROC CA\")");
        RemoteLink* rl = remote_binder_(r, f, l, why);
        if (!rl) return false;
        l.set_device(rl);
        return true;
    }
    std::string_view fname = spec.field.empty() ? std::string_view("VAL") : std::string_view(spec.field);
    const FieldDesc* tf = t->type().find(fname);
    if (!tf) {
        if (f.dbf == Dbf::FwdLink) tf = t->type().find("PROC"); // FLNK "rec.X": the record is processed
        if (!tf) return fail(SB() << "record " << t->name() << " (" << t->type().name() << ") has no field " << fname);
    }
    if (f.dbf == Dbf::OutLink) {
        Address a;
        a.rec = t;
        a.field = tf;
        if (!a.writable())
            return fail(SB() << "field " << tf->name << " of record " << t->name()
                             << (t->val_read_only && is_val(*tf) ? " is set by the system (one writer per output)"
                                                                  : " is read-only"));
    }
    l.set_target(t, tf);
    if (f.dbf == Dbf::InLink && (l.proc == Link::kCp || l.proc == Link::kCpp)) {
        auto w = std::make_unique<CpLinkWatch>(*this, r, f, l.proc == Link::kCpp);
        w->addr.rec = t;
        w->addr.field = tf;
        w->mask = kDbeValue | kDbeAlarm;
        subscribe(*w);
        cp_watches_.push_back(std::move(w));
    }
    l.forget_spec(); // resolved here: the text is rebuilt from the target when asked for
    return true;
}

PutStatus Database::relink(Record& r, const FieldDesc& f, std::string_view text) {
    Link fresh;
    if (!parse_link(text, f.dbf, fresh, nullptr)) return PutStatus::BadValue;
    // drop the CP watch of the old link
    for (auto w = cp_watches_.begin(); w != cp_watches_.end(); ++w)
        if (&(*w)->src() == &r && &(*w)->src_field() == &f) {
            unsubscribe(**w);
            cp_watches_.erase(w);
            break;
        }
    Link& l = field_ref<Link>(r, f);
    if (fresh.state && fresh.state->spec) fresh.state->spec->loc = l.s().loc;
    // a hardware link gives back its output first, so that the new link may claim it again
    if (l.kind == Link::Kind::Hw && l.device()) l.device()->release();
    if (!resolve_link(r, f, fresh, nullptr)) {
        if (!l.remote()) resolve_link(r, f, l, nullptr); // the old link stays, with its watch
        return PutStatus::BadValue;
    }
    if (RemoteLink* old = l.remote()) old->release();
    l = std::move(fresh);
    io_intr_stale_ = true; // an I/O Intr record may now have another device
    return PutStatus::Ok;
}

void Database::add_to_scan(Record& r) {
    auto by_phase = [&](std::vector<Record*>& v) {
        auto at = std::upper_bound(v.begin(), v.end(), r.phas, [](int16_t p, Record* x) { return p < x->phas; });
        v.insert(at, &r);
    };
    double period = scan_period(r.scan);
    bool readback = false; // asyn's info(asyn:READBACK, "1"): an output follows its device
    for (const auto& [k, v] : r.infos())
        if (k == "asyn:READBACK" && v == "1") readback = true;
    if (r.scan == 2 || readback) {
        io_intr_.push_back(IoIntr{&r, {}, nullptr, r.scan != 2});
        io_intr_stale_ = true;
    }
    if (period > 0) {
        auto it = std::find_if(scans_.begin(), scans_.end(), [&](const ScanList& s) { return s.period_s == period; });
        if (it == scans_.end()) {
            scans_.push_back(ScanList{period, 0, {}});
            it = std::prev(scans_.end());
        }
        by_phase(it->recs);
    } else if (r.scan == 1 && r.evnt[0]) {
        by_phase(events_[std::string(r.evnt, strnlen(r.evnt, sizeof r.evnt))]);
    }
}

void Database::scan_io_intr() {
    Depth d(*this);
    if (io_intr_stale_) { // the devices of each record's links, once (not every field every call)
        for (IoIntr& io : io_intr_) {
            io.devices.clear();
            io.readback = nullptr;
            for (const FieldDesc& f : io.rec->type().fields())
                if (is_link(f.dbf))
                    if (LinkDevice* dev = field_ref<Link>(*io.rec, f).device()) {
                        io.devices.push_back(dev);
                        if (f.dbf == Dbf::OutLink && is_named(f, "OUT") && io.rec->type().find("VAL")) io.readback = dev;
                    }
        }
        io_intr_stale_ = false;
    }
    for (std::size_t i = 0; i < io_intr_.size(); ++i) {
        bool changed = false;
        for (LinkDevice* dev : io_intr_[i].devices) changed = dev->changed() || changed;
        if (!changed) continue;
        Record& r = *io_intr_[i].rec;
        double v = 0;
        if (io_intr_[i].readback && !r.pact && io_intr_[i].readback->read(v)) { // an output follows its signal
            const FieldDesc& vf = *r.type().find("VAL");
            Elements e = r.elements(vf);
            double cur = 0;
            get_element(r, vf, e, 0, Prim::Double, &cur);
            put_element(r, vf, e, 0, Prim::Double, &v);
            r.udf = 0;
            if (io_intr_[i].passive) { // read-back only: clients see the new value, nothing is written
                if (cur == v && r.stat != kStatUdf) continue;
                r.stamp_time();
                unsigned m = (cur != v ? kDbeValue | kDbeLog : 0u) | r.reset_alarms(); // no alarm pending: UDF clears
                if (m) post(r, &vf, m);
                continue;
            }
        }
        if (!io_intr_[i].passive) process_record(r);
        if (io_intr_stale_) break; // processing relinked a record: start again at the next call
    }
}

void Database::remove_from_scan(Record& r) {
    io_intr_.erase(std::remove_if(io_intr_.begin(), io_intr_.end(), [&](const IoIntr& io) { return io.rec == &r; }),
                   io_intr_.end());
    io_intr_stale_ = true;
    for (auto& s : scans_) s.recs.erase(std::remove(s.recs.begin(), s.recs.end(), &r), s.recs.end());
    for (auto& [name, v] : events_) v.erase(std::remove(v.begin(), v.end(), &r), v.end());
}

Record* Database::find(std::string_view name) const {
    if (Record* r = records_.find(name)) return r;
    auto a = aliases_.find(name);
    return a == aliases_.end() ? nullptr : a->second;
}

std::vector<Record*> Database::records() const { return order_; }

bool Database::has_record_for(std::string_view channel) const {
    std::size_t dot = channel.find('.');
    std::string_view rec = channel.substr(0, dot);
    Record* r = find(rec);
    if (!r) return false;
    if (dot == std::string_view::npos) return true;
    std::string_view field = channel.substr(dot + 1);
    std::size_t end = 0;
    while (end < field.size() && (std::isalnum(static_cast<unsigned char>(field[end])) || field[end] == '_'))
        ++end;
    field = field.substr(0, end);
    return field.empty() || field == "RTYP" || r->type().find(field);
}

bool Database::resolve(std::string_view channel, Address& out, std::string* why) const {
    auto fail = [&](std::string msg) {
        if (why) *why = std::move(msg);
        return false;
    };
    std::size_t dot = channel.find('.');
    std::string_view rec_name = channel.substr(0, dot);
    Record* r = find(rec_name);
    if (!r) return fail(SB() << "no record " << rec_name);
    std::string_view field = "VAL";
    std::string_view suffix;
    if (dot != std::string_view::npos) {
        std::string_view rest = channel.substr(dot + 1);
        std::size_t end = 0;
        while (end < rest.size() && (std::isalnum(static_cast<unsigned char>(rest[end])) || rest[end] == '_'))
            ++end;
        field = rest.substr(0, end);
        suffix = rest.substr(end);
        if (field.empty()) field = "VAL";
    }
    bool long_string = false;
    if (!suffix.empty() && suffix[0] == '$') {
        long_string = true;
        suffix.remove_prefix(1);
    }
    if (!suffix.empty())
        return fail(SB() << "channel " << channel << ": array ranges and filters (\"" << suffix
                         << "\") are not supported");
    out = Address{};
    out.rec = r;
    if (field == "RTYP") {
        out.kind = Address::Kind::RecordType;
        out.native = Prim::String;
        out.count = 1;
        return true;
    }
    const FieldDesc* fd = r->type().find(field);
    if (!fd) return fail(SB() << "record " << rec_name << " (" << r->type().name() << ") has no field " << field);
    out.field = fd;
    if (long_string && fd->dbf == Dbf::String) {
        out.kind = Address::Kind::LongString;
        out.native = Prim::Char;
        out.count = fd->size;
        return true;
    }
    if ((fd->flags & kLongString) && !long_string) {
        out.kind = Address::Kind::StringHead;
        out.native = Prim::String;
        out.count = 1;
    } else if (fd->flags & kArray) {
        Elements e = r->elements(*fd);
        out.native = native_prim(e.type);
        out.count = e.capacity;
    } else {
        out.native = native_prim(r->elements(*fd).type); // the type as the record serves it now (cvt_dbaddr)
        out.count = 1;
    }
    return true;
}

bool Database::readable_as(const Address& a, Prim t) const {
    if (t == Prim::String) return true;
    std::string_view text; // a string field's text: readable as a number only when it is one
    if (a.kind == Address::Kind::StringHead) {
        Elements e = a.rec->elements(*a.field);
        const char* s = static_cast<const char*>(e.data);
        text = std::string_view(s, strnlen(s, std::min<std::size_t>(e.capacity, kStringSize - 1)));
    } else if (a.kind == Address::Kind::Field && a.field->dbf == Dbf::String && !(a.field->flags & kArray)) {
        const char* s = static_cast<const char*>(a.field->addr(*a.rec));
        text = std::string_view(s, strnlen(s, a.field->size));
    } else {
        return true;
    }
    if (t == Prim::Enum) return false;
    double v;
    return parse_double(text, v);
}

uint32_t Database::current_count(const Address& a) const {
    if (a.kind == Address::Kind::RecordType) return 1;
    if (a.kind == Address::Kind::StringHead) return a.rec->elements(*a.field).count ? 1 : 0;
    if (a.kind == Address::Kind::LongString) {
        const char* s = static_cast<const char*>(a.field->addr(*a.rec));
        return uint32_t(strnlen(s, a.field->size) + 1 > a.field->size ? a.field->size
                                                                       : strnlen(s, a.field->size) + 1);
    }
    if (a.field->flags & kArray) return a.rec->elements(*a.field).count;
    return 1;
}

uint32_t Database::get(const Address& a, Prim t, void* dest, uint32_t n) const {
    const_cast<DatabaseStats&>(stats_).gets++;
    std::size_t esz = prim_size(t);
    char* out = static_cast<char*>(dest);
    if (a.kind == Address::Kind::RecordType) {
        if (n == 0) return 0;
        Elements e{Dbf::String, const_cast<char*>(a.rec->type().name().c_str()), 1, 1,
                   uint16_t(a.rec->type().name().size() + 1)};
        get_element(*a.rec, *a.rec->type().find("NAME"), e, 0, t, out);
        std::memset(out + esz, 0, (n - 1) * esz);
        return 1;
    }
    if (a.kind == Address::Kind::StringHead) { // the first 39 characters (dbGet's getStringString)
        Elements chars = a.rec->elements(*a.field);
        char head[kStringSize] = {};
        const char* s = static_cast<const char*>(chars.data);
        std::memcpy(head, s, strnlen(s, std::min<std::size_t>(chars.capacity, kStringSize - 1)));
        uint32_t valid = chars.count ? 1 : 0;
        if (n && valid) get_element(*a.rec, *a.field, Elements{Dbf::String, head, 1, 1, kStringSize}, 0, t, out);
        std::memset(out + valid * esz, 0, (n - std::min(n, valid)) * esz);
        return valid;
    }
    if (a.kind == Address::Kind::LongString) {
        const char* s = static_cast<const char*>(a.field->addr(*a.rec));
        uint32_t len = uint32_t(strnlen(s, a.field->size));
        uint32_t valid = std::min<uint32_t>(len + 1, a.field->size);
        Elements e{Dbf::UChar, const_cast<char*>(s), valid, a.field->size, 1};
        uint32_t k = 0;
        for (; k < std::min(n, valid); ++k) get_element(*a.rec, *a.field, e, k, t, out + k * esz);
        std::memset(out + k * esz, 0, (n - k) * esz);
        return valid;
    }
    Elements e = a.rec->elements(*a.field);
    uint32_t k = 0;
    uint32_t valid = std::min(n, e.count);
    if (t == Prim::Double && e.type == Dbf::Double) {
        std::memcpy(out, e.data, std::size_t(valid) * 8);
        k = valid;
    } else {
        for (; k < valid; ++k) get_element(*a.rec, *a.field, e, k, t, out + k * esz);
    }
    if (k < n) std::memset(out + std::size_t(k) * esz, 0, std::size_t(n - k) * esz);
    return e.count;
}

PutStatus Database::put(const Address& a, Prim t, const void* data, uint32_t n, PutCallback cb) {
    stats_.puts++;
    // A refusal answers the put-callback too (every put gets its completion): a read-only field,
    // or DISP set and the field not DISP (base's dbNotify putDisabledType: notifyError, PUTFAIL).
    if (!a.writable() || (a.rec->disp && !is_named(*a.field, "DISP"))) {
        stats_.bad_puts++;
        PutStatus st = a.writable() ? PutStatus::Failed : PutStatus::ReadOnly;
        if (cb) cb(st);
        return st;
    }
    Depth depth(*this);
    Record& r = *a.rec;
    bool busy = r.pact && !r.in_process_; // asynchronous processing in progress (dbNotify: restart)
    // A link field is put and answered at once, never processed (dbProcessNotify's DBF_xxxLINK case).
    if (cb && !is_link(a.field->dbf) && (busy || (r.notify_ && (r.notify_->active || !r.notify_->queue.empty())))) {
        // Another put-callback is in progress on this record, or the record is busy: wait behind
        // it (arrival order); the put, its processing and its callback follow the completion.
        const char* p = static_cast<const char*>(data);
        if (!r.notify_) r.notify_ = std::make_unique<NotifyState>();
        r.notify_->queue.push_back(
            {a, t, std::vector<char>(p, p + std::size_t(n) * prim_size(t)), n, std::move(cb)});
        return PutStatus::Ok;
    }
    return do_put(a, t, data, n, std::move(cb));
}

PutStatus Database::store(const Address& a, Prim t, const void* data, uint32_t n) {
    Record& r = *a.rec;
    const FieldDesc& f = *a.field;
    const char* src = static_cast<const char*>(data);
    std::size_t esz = prim_size(t);
    auto fail = [](PutStatus st) { return st; };
    if (n == 0) return fail(PutStatus::BadValue);

    if (a.kind == Address::Kind::StringHead) { // one string (a number: its text) into the chars
        char text[kStringSize] = {};
        if (!put_element(r, kScratchString, Elements{Dbf::String, text, 1, 1, kStringSize}, 0, t, src))
            return fail(PutStatus::BadValue);
        Address chars = a;
        chars.kind = Address::Kind::Field;
        return store(chars, Prim::Char, text, uint32_t(strnlen(text, kStringSize - 1) + 1));
    }
    if (is_link(f.dbf)) { // a new link: parsed and resolved now, or refused (the old one stays)
        char text[kStringSize];
        if (t == Prim::String) {
            copy_string(text, sizeof text, std::string_view(src, strnlen(src, kStringSize)));
        } else if (t == Prim::Char) {
            copy_string(text, sizeof text, std::string_view(src, strnlen(src, std::min<std::size_t>(n, sizeof text - 1))));
        } else {
            return fail(PutStatus::BadValue);
        }
        PutStatus st = relink(r, f, text);
        if (st != PutStatus::Ok) return fail(st);
    } else if (a.kind == Address::Kind::LongString) {
        // A char array written to a string field: up to the first NUL, truncated to the field.
        std::string s;
        for (uint32_t k = 0; k < n; ++k) {
            char c;
            if (t == Prim::Char) c = src[k];
            else {
                Elements tmp{Dbf::UChar, &c, 1, 1, 1};
                if (!put_element(r, f, tmp, 0, t, src + k * esz)) return fail(PutStatus::BadValue);
            }
            if (!c) break;
            s.push_back(c);
        }
        std::vector<char> old(f.size);
        std::memcpy(old.data(), f.addr(r), f.size);
        copy_string(static_cast<char*>(f.addr(r)), f.size, s);
        PutStatus st = r.special(f);
        if (st != PutStatus::Ok) {
            std::memcpy(f.addr(r), old.data(), f.size);
            return fail(st);
        }
    } else if (f.flags & kArray) {
        Elements e = r.elements(f);
        uint32_t m = std::min(n, e.capacity);
        // Convert into a scratch copy first so a bad element changes nothing.
        std::vector<char> scratch(std::size_t(m) * e.stride);
        Elements s = e;
        s.data = scratch.data();
        for (uint32_t k = 0; k < m; ++k)
            if (!put_element(r, f, s, k, t, src + k * esz)) return fail(PutStatus::BadValue);
        std::vector<char> old(scratch.size()); // a refused put changes nothing
        std::memcpy(old.data(), e.data, old.size());
        uint32_t old_count = e.count;
        std::memcpy(e.data, scratch.data(), scratch.size());
        r.set_count(f, m);
        PutStatus st = r.special(f);
        if (st == PutStatus::Ok && r.put_hook) st = r.put_hook(r, f);
        if (st != PutStatus::Ok) {
            std::memcpy(e.data, old.data(), old.size());
            r.set_count(f, old_count);
            return fail(st);
        }
    } else {
        Elements e = r.elements(f);
        char old[64];
        std::size_t sz = std::min<std::size_t>(f.size, sizeof old);
        std::memcpy(old, e.data, sz);
        if (!put_element(r, f, e, 0, t, src)) return fail(PutStatus::BadValue);
        PutStatus st = r.special(f);
        if (st == PutStatus::Ok && r.put_hook) st = r.put_hook(r, f);
        if (st != PutStatus::Ok) {
            std::memcpy(e.data, old, sz);
            return fail(st);
        }
    }

    bool val = is_val(f);
    if (val) r.udf = 0;
    if (!val || !(f.flags & kProcess)) post(r, &f, kDbeValue | kDbeLog); // VAL: processing posts it
    if (f.flags & kProp) post(r, nullptr, kDbeProperty);
    if (f.flags & kScanField) {
        remove_from_scan(r);
        add_to_scan(r);
    }
    return PutStatus::Ok;
}

PutStatus Database::do_put(const Address& a, Prim t, const void* data, uint32_t n, PutCallback cb) {
    Record& r = *a.rec;
    const FieldDesc& f = *a.field;
    PutStatus st = store(a, t, data, n);
    if (st != PutStatus::Ok) {
        stats_.bad_puts++;
        if (cb) cb(st);
        return st;
    }
    // dbPutField: PROC always processes; another pp field only a Passive record. A record
    // that is busy (asynchronous) is processed again when it completes (RPRO).
    bool proc = (f.flags & kProcField) || ((f.flags & kProcess) && r.scan == 0);
    if (proc && r.pact) {
        r.rpro = 1;
    } else if (proc) {
        PutNotify* pn = nullptr;
        if (cb) {
            if (!r.notify_) r.notify_ = std::make_unique<NotifyState>();
            r.notify_->active = std::move(cb);
            pn = new PutNotify;
            pn->origin = &r;
        }
        PutNotify* outer = notify_;
        notify_ = pn; // records this processing reaches join the put-callback
        r.putf = 1;
        process_record(r);
        r.putf = 0;
        notify_ = outer;
        if (pn) {
            pn->started = true;
            if (pn->pending == 0) finish_notify(pn);
        }
        return PutStatus::Ok;
    }
    if (cb) cb(PutStatus::Ok);
    return PutStatus::Ok;
}

void Database::finish_notify(PutNotify* pn) {
    Record* origin = pn->origin;
    PutStatus st = pn->status;
    delete pn;
    if (origin) notify_complete(*origin, st);
}

void Database::async_complete(Record& r, PutStatus st) {
    if (r.in_process_) { // completed before process() returned: the processing is synchronous
        r.done_in_process_ = true;
        r.done_status_ = st;
    }
    if (PutNotify* pn = r.pn_) {
        r.pn_ = nullptr;
        if (st != PutStatus::Ok && pn->status == PutStatus::Ok) pn->status = st;
        if (--pn->pending == 0 && pn->started) finish_notify(pn);
    }
    if (r.in_process_) return; // process_record goes on (RPRO, FLNK) once process() returns
    Depth depth(*this);
    // recGblFwdLink of an asynchronous completion: processed again if a put came meanwhile (RPRO),
    // then the put-callbacks that waited for the record to finish (dbNotify's restart list).
    if (r.rpro) {
        r.rpro = 0;
        scan_once(r);
    }
    if (!r.pact) restart_waiting(r);
}

void Database::link_put_done(Record& r, bool ok) {
    if (!r.link_wait_) return;
    r.link_wait_ = false;
    if (r.in_process_) return; // completed at once: process_record goes on
    Depth depth(*this);
    link_forward(r, r.flnk); // recGblFwdLink of the second pass (PACT still set)
    if (!ok) stats_.link_errors++;
    r.async_done(ok ? PutStatus::Ok : PutStatus::Failed); // a refused remote put never reports success
}

void Database::restart_waiting(Record& r) {
    while (r.notify_ && !r.notify_->active && !r.notify_->queue.empty() && !r.pact) {
        NotifyState::Queued q = std::move(r.notify_->queue.front());
        r.notify_->queue.pop_front();
        do_put(q.addr, q.type, q.data.data(), q.count, std::move(q.cb));
    }
}

bool Database::disabled(Record& r) {
    if (!r.sdis.empty() && !r.sdis.is_constant()) {
        int16_t v = r.disa;
        uint32_t got = 0;
        if (link_get(r, r.sdis, Prim::Short, &v, 1, &got) && got) r.disa = v;
    }
    if (r.disa != r.disv) return false;
    if (r.stat != kStatDisable || r.sevr != r.diss) {
        r.nsta = 0;
        r.nsev = 0;
        r.stat = kStatDisable;
        r.sevr = r.diss;
        r.post("STAT", kDbeValue);
        r.post("SEVR", kDbeValue);
        if (const FieldDesc* v = r.type().find("VAL")) post(r, v, kDbeValue | kDbeAlarm);
    }
    return true;
}

void Database::process_record(Record& r) {
    if (r.pact) { // busy (asynchronous, or a loop back to a record being processed): skipped
        if (r.lcnt < 255) ++r.lcnt;
        return;
    }
    r.lcnt = 0;
    if (disabled(r)) return;
    if (r.tpro) std::printf("%s: dbProcess of '%.*s'\n", notify_ ? "putNotify" : "scan", int(r.name().size()),
                            r.name().data());
    stats_.processes++;
    r.in_process_ = true;
    r.done_in_process_ = false;
    ProcessResult res = r.process();
    r.in_process_ = false;
    if (r.link_wait_ && res == ProcessResult::Done) { // an Async Soft Channel put is on its way
        r.pact = 1;
        res = ProcessResult::Async;
    }
    if (res == ProcessResult::Async && !r.done_in_process_) {
        if (notify_ && !r.pn_) { // the put-callback waits for this record too
            r.pn_ = notify_;
            ++notify_->pending;
        }
        return;
    }
    if (r.done_in_process_ && r.done_status_ != PutStatus::Ok && notify_ && notify_->status == PutStatus::Ok)
        notify_->status = r.done_status_;
    r.done_in_process_ = false;
    if (res == ProcessResult::Done) { // recGblFwdLink (asynchronous records call fwd_link themselves)
        uint8_t was = r.pact;
        r.pact = 1; // a forward link back to this record does not process it again
        link_forward(r, r.flnk);
        r.pact = was;
    }
    if (r.rpro) {
        r.rpro = 0;
        scan_once(r);
    }
}

void Database::scan_once(Record& r) {
    once_.push_back(&r);
    if (depth_ == 0) Depth d(*this); // nothing in progress: run it now
}

void Database::post_event(std::string_view name) {
    auto it = events_.find(std::string(name));
    if (it == events_.end()) return;
    // As an event scan task: the records run after the processing that posted the event.
    Depth d(*this);
    for (Record* r : it->second) once_.push_back(r);
}

void Database::link_forward(Record& r, Link& l) {
    (void)r;
    if (RemoteLink* rl = l.remote()) { // CA FLNK: PROC = 1 on the other server
        int16_t one = 1;
        if (!rl->put(Prim::Short, &one, 1)) stats_.link_errors++;
        return;
    }
    if (l.kind != Link::Kind::Db || !l.target()) return;
    PutNotify* outer = notify_;
    if (r.pn_) notify_ = r.pn_; // an asynchronous record's forward link belongs to its put-callback
    if (l.target()->scan == 0 || (l.target_field()->flags & kProcField)) process_record(*l.target());
    notify_ = outer;
}

bool Database::link_get(Record& r, Link& l, Prim t, void* dest, uint32_t n, uint32_t* got) {
    *got = 0;
    switch (l.kind) {
    case Link::Kind::Empty:
    case Link::Kind::Constant: return true;
    case Link::Kind::Hw: {
        double v = 0;
        if (!l.device()) break;
        if (l.device()->is_text()) { // a string, a CHAR array (NUL included), or its number
            std::string text;
            bool ok = l.device()->read_text(text);
            if (!ok) {
                stats_.link_errors++;
                r.set_sevr(l.device()->read_alarm(), kInvalid);
            }
            if (t == Prim::String) {
                copy_string(static_cast<char*>(dest), kStringSize, text);
                *got = 1;
            } else if (t == Prim::Char && n > 1) {
                uint32_t len = std::min<uint32_t>(uint32_t(text.size()), n - 1);
                std::memcpy(dest, text.data(), len);
                static_cast<char*>(dest)[len] = 0;
                *got = len + 1;
            } else {
                if (!parse_double(text.c_str(), v)) return false;
                Elements e{Dbf::Double, &v, 1, 1, 8};
                get_element(r, kScratchDouble, e, 0, t, dest);
                *got = 1;
            }
            return true;
        }
        if (!l.device()->read(v)) {
            stats_.link_errors++;
            r.set_sevr(l.device()->read_alarm(), kInvalid);
            return false;
        }
        Elements e{Dbf::Double, &v, 1, 1, 8};
        get_element(r, kScratchDouble, e, 0, t, dest);
        *got = 1;
        return true;
    }
    case Link::Kind::Db: {
        if (RemoteLink* rl = l.remote()) { // CA link: the last value its monitor received
            RemoteLink::Value v;
            if (!rl->value(v)) break;
            if (t == Prim::String && v.enum_string && n >= 1) { // an enum read as text: its state string
                std::memset(dest, 0, kStringSize);
                std::strncpy(static_cast<char*>(dest), v.enum_string, kStringSize - 1);
                *got = 1;
                r.inherit_sevr(l.ms, v.stat, v.sevr);
                return true;
            }
            const FieldDesc& sf = scratch_field(v.type);
            Elements e{sf.dbf, const_cast<void*>(v.data), v.count, v.count, uint16_t(prim_size(v.type))};
            uint32_t k = std::min(v.count, n);
            for (uint32_t i = 0; i < k; ++i) get_element(r, sf, e, i, t, static_cast<char*>(dest) + i * prim_size(t));
            *got = k;
            r.inherit_sevr(l.ms, v.stat, v.sevr);
            return true;
        }
        if (!l.target()) break;
        Record& tr = *l.target();
        if (l.proc == Link::kPp && tr.scan == 0 && &tr != &r) process_record(tr);
        Address a;
        a.rec = &tr;
        a.field = l.target_field();
        a.native = native_prim(l.target_field()->dbf);
        a.count = (l.target_field()->flags & kArray) ? tr.elements(*l.target_field()).capacity : 1;
        as_string_head(a, t, n);
        uint32_t c = get(a, t, dest, n);
        *got = std::min(c, n);
        r.inherit_sevr(l.ms, tr.stat, tr.sevr);
        return true;
    }
    }
    stats_.link_errors++;
    r.set_sevr(kStatLink, kInvalid);
    return false;
}

bool Database::link_put(Record& r, Link& l, Prim t, const void* src, uint32_t n) {
    switch (l.kind) {
    case Link::Kind::Empty:
    case Link::Kind::Constant: return true;
    case Link::Kind::Hw: {
        double v = 0;
        Elements e{Dbf::Double, &v, 1, 1, 8};
        if (l.device() && put_element(r, kScratchDouble, e, 0, t, src) && l.device()->write(v)) return true;
        break;
    }
    case Link::Kind::Db: {
        if (RemoteLink* rl = l.remote()) { // CA link: a put, not waited for
            if (r.in_process_ && !r.link_wait_ && async_soft(r)) {
                // devAoSoftCallback & co: the record stays busy (PACT) until the remote put completed;
                // monitors were posted, FLNK and a put-callback wait (link_put_done).
                r.link_wait_ = true;
                Record* rec = &r;
                if (rl->put_notify(t, src, n, [this, rec](bool ok) { link_put_done(*rec, ok); })) return true;
                r.link_wait_ = false;
                break;
            }
            if (rl->put(t, src, n)) return true;
            break;
        }
        if (!l.target()) break;
        Record& tr = *l.target();
        const FieldDesc& tf = *l.target_field();
        Address a;
        a.rec = &tr;
        a.field = &tf;
        a.native = native_prim(tf.dbf);
        a.count = (tf.flags & kArray) ? tr.elements(tf).capacity : 1;
        as_string_head(a, t, n);
        if (!a.writable() || is_link(tf.dbf) || store(a, t, src, n) != PutStatus::Ok) break;
        tr.inherit_sevr(l.ms, r.nsta, r.nsev);
        if ((tf.flags & kProcField) || (l.proc == Link::kPp && tr.scan == 0)) process_record(tr);
        return true;
    }
    }
    stats_.link_errors++;
    r.set_sevr(kStatLink, kInvalid);
    return false;
}

bool Database::link_read(Record& r, Link& l, const FieldDesc& f) {
    Elements e = r.elements(f);
    uint32_t got = 0;
    if (f.flags & kArray) {
        Prim p = native_prim(e.type);
        std::vector<char> buf(std::size_t(e.capacity) * prim_size(p));
        if (!link_get(r, l, p, buf.data(), e.capacity, &got)) return false;
        if (l.kind != Link::Kind::Db && l.kind != Link::Kind::Hw) return true;
        for (uint32_t k = 0; k < got; ++k) put_element(r, f, e, k, p, buf.data() + std::size_t(k) * prim_size(p));
        r.set_count(f, got);
        return true;
    }
    Prim p = transfer_prim(f.dbf, source_dbf(l));
    alignas(8) char buf[kStringSize] = {};
    if (!link_get(r, l, p, buf, 1, &got)) return false;
    if (!got) return true;
    if (put_element(r, f, e, 0, p, buf)) return true;
    stats_.link_errors++;
    r.set_sevr(kStatLink, kInvalid); // e.g. a string that is not a number
    return false;
}

bool Database::link_read(Record& r, Link& l, double& v) {
    Prim p = source_dbf(l) == Dbf::String ? Prim::String : Prim::Double;
    alignas(8) char buf[kStringSize] = {};
    uint32_t got = 0;
    if (!link_get(r, l, p, buf, 1, &got)) return false;
    if (!got) return true;
    if (p == Prim::Double) {
        std::memcpy(&v, buf, sizeof v);
        return true;
    }
    if (parse_double(buf, v)) return true;
    stats_.link_errors++;
    r.set_sevr(kStatLink, kInvalid);
    return false;
}

bool Database::link_write(Record& r, Link& l, const FieldDesc& f) {
    Elements e = r.elements(f);
    if (f.flags & kArray) {
        Prim p = native_prim(e.type);
        std::vector<char> buf(std::size_t(std::max<uint32_t>(e.count, 1)) * prim_size(p));
        for (uint32_t k = 0; k < e.count; ++k) get_element(r, f, e, k, p, buf.data() + std::size_t(k) * prim_size(p));
        return link_put(r, l, p, buf.data(), std::max<uint32_t>(e.count, 1));
    }
    Prim p = transfer_prim(source_dbf(l), f.dbf);
    alignas(8) char buf[kStringSize] = {};
    get_element(r, f, e, 0, p, buf);
    return link_put(r, l, p, buf, 1);
}

bool Database::link_write(Record& r, Link& l, double v) {
    Prim p = source_dbf(l) == Dbf::String ? Prim::String : Prim::Double;
    alignas(8) char buf[kStringSize] = {};
    Elements e{Dbf::Double, &v, 1, 1, 8};
    get_element(r, kScratchDouble, e, 0, p, buf);
    return link_put(r, l, p, buf, 1);
}

void Database::notify_complete(Record& r, PutStatus st) {
    if (!r.notify_) return;
    if (r.notify_->active) {
        PutCallback cb = std::move(r.notify_->active);
        r.notify_->active = nullptr;
        cb(st);
    }
    restart_waiting(r);
}

void Database::process(Record& r) {
    Depth d(*this);
    process_record(r);
}

void Database::subscribe(Subscription& s) { s.addr.rec->subs_.push_back(&s); }

void Database::unsubscribe(Subscription& s) {
    auto& v = s.addr.rec->subs_;
    v.erase(std::remove(v.begin(), v.end(), &s), v.end());
}

void Database::observe(Record& r, RecordObserver& o) { r.observers_.push_back(&o); }

void Database::unobserve(Record& r, RecordObserver& o) {
    auto& v = r.observers_;
    v.erase(std::remove(v.begin(), v.end(), &o), v.end());
}

void Database::post(Record& r, const FieldDesc* f, unsigned mask) {
    if (r.subs_.empty()) return;
    stats_.posts++;
    // Index loop: a subscriber may not add or remove subscriptions while being told.
    for (std::size_t i = 0; i < r.subs_.size(); ++i) {
        Subscription* s = r.subs_[i];
        if (f && s->addr.field != f) continue;
        if (s->addr.kind == Address::Kind::RecordType && f) continue;
        unsigned m = mask & s->mask;
        if (m) s->on_event(m);
    }
}

void Database::call_after(Record& r, double seconds, int tag) {
    delays_.push_back({&r, (clock_ ? clock_() : now_s_) + std::max(0.0, seconds), tag});
}

void Database::note_record_error(const Record& r, const std::string& why) {
    std::string m = SB() << "record " << r.name() << ": " << why;
    LOG_ERR(lg, m);
    record_errors_.push_back(std::move(m));
}

void Database::rescan(Record& r) {
    remove_from_scan(r);
    add_to_scan(r);
}

void Database::scan_periodic(double now_s) {
    Depth d(*this);
    now_s_ = now_s;
    if (ioc_stats_) ioc_stats_->tick(*this, now_s);
    for (std::size_t i = 0; i < delays_.size();) { // in order of request; a callback may add more
        if (delays_[i].next_s > now_s) {
            ++i;
            continue;
        }
        Record* r = delays_[i].rec;
        int tag = delays_[i].tag;
        delays_.erase(delays_.begin() + std::ptrdiff_t(i));
        r->on_delay(tag);
    }
    for (auto& s : scans_) {
        if (s.next_s == 0) s.next_s = now_s;
        if (now_s < s.next_s) continue;
        s.next_s += s.period_s;
        if (s.next_s < now_s) s.next_s = now_s + s.period_s; // fell behind: skip, don't burst
        // by index: processing may move a record to another list (a put to its SCAN)
        for (std::size_t i = 0; i < s.recs.size(); ++i) process_record(*s.recs[i]);
    }
    for (std::size_t i = 0; i < polls_.size(); ++i) {
        Poll& p = polls_[i];
        if (now_s < p.next_s) continue;
        double period = p.rec->poll_period_s();
        p.next_s = p.next_s == 0 || p.next_s + period < now_s ? now_s + period : p.next_s + period;
        p.rec->poll_tick();
    }
}

void Database::write_db(std::ostream& os) const {
    std::map<std::string, std::unique_ptr<Record>> defaults;
    for (Record* r : order_) {
        auto& def = defaults[r->type().name()];
        if (!def) def = r->type().create();
        os << "record(" << r->type().name() << ", \"" << r->name() << "\") {\n";
        for (const FieldDesc& f : r->type().fields()) {
            if (f.flags & (kReadOnly | kArray)) continue;
            if (std::strcmp(f.name, "UDF") == 0) continue;
            std::string v = format_field(*r, f);
            if (v == format_field(*def, f)) continue;
            os << "    field(" << f.name << ", \"";
            for (char c : v) {
                if (c == '"' || c == '\\') os << '\\';
                os << c;
            }
            os << "\")\n";
        }
        for (auto& [k, v] : r->info_) os << "    info(" << k << ", \"" << v << "\")\n";
        for (auto& a : r->aliases_) os << "    alias(\"" << a << "\")\n";
        os << "}\n";
    }
}

} // namespace beamctl::pv
