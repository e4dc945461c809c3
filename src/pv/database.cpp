#include "pv/database.hpp"

#include "core/error.hpp"
#include "pv/convert.hpp"

#include <algorithm>
#include <cstring>

namespace beamctl::pv {

bool Address::writable() const {
    if (kind == Kind::RecordType || !field) return false;
    if (rec->val_read_only && field->name[0] == 'V' && std::strcmp(field->name, "VAL") == 0) return false;
    return !(field->flags & (kReadOnly | kInitOnly));
}

int Address::asl() const { return field && (field->flags & kAsl0) ? 0 : 1; }

Database::Database() = default;

Database::~Database() {
    for (auto* r : order_) r->db_ = nullptr;
}

namespace {
bool is_val(const FieldDesc& f) { return f.name[0] == 'V' && f.name[1] == 'A' && f.name[2] == 'L' && !f.name[3]; }

double scan_period(uint16_t scan) {
    static const double periods[] = {0, 0, 0, 10, 5, 2, 1, 0.5, 0.2, 0.1};
    return scan < 10 ? periods[scan] : 0;
}
} // namespace

void Database::apply_field(Record& rec, const DbField& f, const std::string& file) {
    (void)file;
    const FieldDesc* fd = rec.type().find(f.name);
    if (!fd)
        throw Error(SB() << f.loc.str() << ": record type " << rec.type().name() << " has no field "
                         << f.name << " (record " << rec.name() << ")");
    if (fd->flags & kReadOnly)
        throw Error(SB() << f.loc.str() << ": field " << f.name << " of record " << rec.name()
                         << " is read-only");
    if (fd->flags & kArray)
        throw Error(SB() << f.loc.str() << ": field " << f.name << " of record " << rec.name()
                         << " is an array; initial array values are not supported");
    std::string err;
    if (!parse_field(rec, *fd, f.value, &err))
        throw Error(SB() << f.loc.str() << ": record " << rec.name() << ": " << err);
    if (fd->menu == &kMenuScan) {
        uint16_t s = rec.scan;
        if (s == 1 || s == 2)
            throw Error(SB() << f.loc.str() << ": record " << rec.name() << ": SCAN \""
                             << fd->menu->choices[s]
                             << "\" is not supported for soft records (use Passive or a period)");
    }
    if (is_val(*fd)) rec.udf = 0; // a VAL given in the file defines the value
}

void Database::load(const DbFile& file, const RecordTypes& types) {
    // Validate and build everything first, so a file with an error adds nothing.
    struct Pending {
        std::unique_ptr<Record> fresh; // new record, or null when merging into an existing one
        Record* rec;
    };
    std::vector<Pending> todo;
    std::unordered_map<std::string, Record*> created;
    for (const DbRecord& dr : file.records) {
        Record* existing = find(dr.name);
        if (!existing) {
            auto it = created.find(dr.name);
            if (it != created.end()) existing = it->second;
        }
        if (existing) {
            if (dr.type != "*" && dr.type != existing->type().name())
                throw Error(SB() << dr.loc.str() << ": record " << dr.name << " already exists with type "
                                 << existing->type().name() << ", not " << dr.type);
            for (const DbField& f : dr.fields) apply_field(*existing, f, dr.loc.file);
            continue;
        }
        if (dr.type == "*")
            throw Error(SB() << dr.loc.str() << ": record(\"*\", \"" << dr.name
                             << "\") modifies a record that does not exist");
        const RecordType* t = types.find(dr.type);
        if (!t) {
            SB sb;
            sb << dr.loc.str() << ": unknown record type '" << dr.type << "' (supported:";
            for (auto& n : types.names()) sb << " " << n;
            sb << ")";
            throw Error(sb);
        }
        if (dr.name.empty() || dr.name.size() > 60)
            throw Error(SB() << dr.loc.str() << ": record name '" << dr.name
                             << "' must have 1 to 60 characters");
        for (char c : dr.name)
            if (c == '.' || c == ' ' || c == '"' || c == '\'' || c == '$' || c == '{' || c == '}')
                throw Error(SB() << dr.loc.str() << ": record name '" << dr.name
                                 << "' contains the character '" << c << "'");
        auto rec = t->create();
        copy_string(rec->name_, sizeof rec->name_, dr.name);
        for (const DbField& f : dr.fields) apply_field(*rec, f, dr.loc.file);
        for (const DbInfo& i : dr.infos) rec->info_.emplace_back(i.name, i.value);
        for (const std::string& a : dr.aliases) rec->aliases_.push_back(a);
        created[dr.name] = rec.get();
        Record* raw = rec.get();
        todo.push_back({std::move(rec), raw});
    }
    for (const DbAlias& a : file.aliases) {
        if (!find(a.record) && !created.count(a.record))
            throw Error(SB() << a.loc.str() << ": alias '" << a.alias << "' names record '" << a.record
                             << "' which does not exist");
    }
    for (auto& p : todo) {
        for (auto& a : p.rec->aliases_)
            if (find(a) || created.count(a))
                throw Error(SB() << "alias '" << a << "' of record " << p.rec->name()
                                 << " clashes with an existing name");
    }
    for (auto& p : todo) add(std::move(p.fresh));
    for (auto& p : todo)
        for (auto& a : p.rec->aliases_) aliases_[a] = p.rec;
    for (const DbAlias& a : file.aliases) {
        if (find(a.alias)) throw Error(SB() << a.loc.str() << ": alias '" << a.alias << "' already exists");
        Record* r = find(a.record);
        aliases_[a.alias] = r;
        r->aliases_.push_back(a.alias);
    }
}

Record& Database::add(std::unique_ptr<Record> rec) {
    std::string name(rec->name());
    if (find(name)) throw Error(SB() << "record " << name << " already exists");
    rec->db_ = this;
    Record* raw = rec.get();
    records_.emplace(name, std::move(rec));
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
    auto it = records_.find(name);
    if (it == records_.end()) return;
    Record* r = it->second.get();
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
    for (auto& s : scans_) s.recs.erase(std::remove(s.recs.begin(), s.recs.end(), r), s.recs.end());
    records_.erase(it);
}

void Database::init_records() {
    std::vector<Record*> batch;
    batch.swap(uninitialised_);
    for (Record* r : batch) {
        try {
            r->init();
        } catch (const Error& e) {
            throw Error(SB() << "record " << r->name() << ": " << e.what());
        }
        double period = scan_period(r->scan);
        if (period > 0) {
            auto it = std::find_if(scans_.begin(), scans_.end(),
                                   [&](const ScanList& s) { return s.period_s == period; });
            if (it == scans_.end()) {
                scans_.push_back(ScanList{period, 0, {}});
                it = std::prev(scans_.end());
            }
            it->recs.push_back(r);
        }
    }
    for (Record* r : batch)
        if (r->pini == 1) process(*r);
}

Record* Database::find(std::string_view name) const {
    auto it = records_.find(name);
    if (it != records_.end()) return it->second.get();
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
    if (fd->flags & kArray) {
        Elements e = r->elements(*fd);
        out.native = native_prim(e.type);
        out.count = e.capacity;
    } else {
        out.native = native_prim(fd->dbf);
        out.count = 1;
    }
    return true;
}

uint32_t Database::current_count(const Address& a) const {
    if (a.kind == Address::Kind::RecordType) return 1;
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
    if (!a.writable()) {
        stats_.bad_puts++;
        return PutStatus::ReadOnly;
    }
    Record& r = *a.rec;
    if (cb && r.notify_ && (r.notify_->active || !r.notify_->queue.empty())) {
        // Another put-callback is in progress on this record: wait behind it (arrival order).
        const char* p = static_cast<const char*>(data);
        r.notify_->queue.push_back(
            {a, t, std::vector<char>(p, p + std::size_t(n) * prim_size(t)), n, std::move(cb)});
        return PutStatus::Ok;
    }
    return do_put(a, t, data, n, std::move(cb));
}

PutStatus Database::do_put(const Address& a, Prim t, const void* data, uint32_t n, PutCallback cb) {
    Record& r = *a.rec;
    const FieldDesc& f = *a.field;
    const char* src = static_cast<const char*>(data);
    std::size_t esz = prim_size(t);
    auto fail = [&](PutStatus st) {
        stats_.bad_puts++;
        if (cb) cb(st);
        return st;
    };
    if (n == 0) return fail(PutStatus::BadValue);

    if (a.kind == Address::Kind::LongString) {
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
    if (!val) post(r, &f, kDbeValue | kDbeLog);
    if (f.flags & kProp) post(r, nullptr, kDbeProperty);
    if ((f.flags & kProcess) && !r.pact) {
        if (cb) {
            if (!r.notify_) r.notify_ = std::make_unique<NotifyState>();
            r.notify_->active = std::move(cb);
        }
        stats_.processes++;
        if (r.process() == ProcessResult::Done && r.notify_ && r.notify_->active)
            notify_complete(r, PutStatus::Ok);
        return PutStatus::Ok;
    }
    if (cb) cb(PutStatus::Ok);
    return PutStatus::Ok;
}

void Database::notify_complete(Record& r, PutStatus st) {
    if (!r.notify_) return;
    if (r.notify_->active) {
        PutCallback cb = std::move(r.notify_->active);
        r.notify_->active = nullptr;
        cb(st);
    }
    while (r.notify_ && !r.notify_->active && !r.notify_->queue.empty()) {
        NotifyState::Queued q = std::move(r.notify_->queue.front());
        r.notify_->queue.pop_front();
        do_put(q.addr, q.type, q.data.data(), q.count, std::move(q.cb));
    }
}

void Database::process(Record& r) {
    if (r.pact) return;
    stats_.processes++;
    r.process();
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

void Database::scan_periodic(double now_s) {
    for (auto& s : scans_) {
        if (s.next_s == 0) s.next_s = now_s;
        if (now_s < s.next_s) continue;
        s.next_s += s.period_s;
        if (s.next_s < now_s) s.next_s = now_s + s.period_s; // fell behind: skip, don't burst
        for (Record* r : s.recs) process(*r);
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
