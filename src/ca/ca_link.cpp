#include "ca/ca_link.hpp"

#include "core/error.hpp"
#include "core/log.hpp"

#include <algorithm>
#include <cstring>

namespace beamctl::ca {
namespace {
log::Logger lg("ca.link");
}

class CaLinks::Link : public pv::RemoteLink {
public:
    Link(pv::Database& db, pv::Record& rec, const pv::FieldDesc& f, uint8_t proc, std::string name)
        : db_(db), rec_(rec), input_(f.dbf == pv::Dbf::InLink), proc_(proc), name_(std::move(name)) {}

    void attach(Client& client) {
        if (released_ || ch_) return;
        ch_ = client.channel(name_);
        ch_->on_connection([this](bool up) {
            if (released_) return;
            LOG_DEBUG(lg, "record " << rec_.name() << ": " << name_ << (up ? " connected" : " disconnected"));
            if (!up) {
                have_ = false;
                have_string_ = false;
                scan_if_cp(); // the record sees the disconnection (LINK/INVALID), as dbCa
                return;
            }
            // An enum is monitored as its state string too, for fields that read it as text (dbCa).
            if (input_ && ch_->native_type() == pv::Prim::Enum && !str_mon_)
                str_mon_ = ch_->monitor(pv::kDbeValue | pv::kDbeAlarm, [this](const Result& r) {
                    if (released_) return;
                    have_string_ = r.ok() && r.value.count >= 1 && r.value.data.size() >= std::size_t(pv::kStringSize);
                    if (have_string_) std::memcpy(string_, r.value.data.data(), pv::kStringSize);
                    string_[pv::kStringSize - 1] = 0;
                    scan_if_cp(); // the same event's native value came just before
                }, 14 /* DBR_TIME_STRING */);
            else if (ch_->native_type() != pv::Prim::Enum)
                str_mon_.reset();
        });
        if (input_)
            mon_ = ch_->monitor(pv::kDbeValue | pv::kDbeAlarm, [this](const Result& r) {
                if (released_) return;
                have_ = r.ok();
                if (have_) last_ = r.value;
                if (!(str_mon_ && have_ && last_.prim == pv::Prim::Enum)) scan_if_cp(); // else after its string

            });
    }

    bool value(Value& out) const override {
        if (!have_ || !ch_ || !ch_->connected()) return false;
        out.type = last_.prim;
        out.count = last_.count;
        out.data = last_.data.data();
        out.stat = last_.status;
        out.sevr = last_.severity;
        out.time = last_.stamp;
        out.enum_string = last_.prim == pv::Prim::Enum && have_string_ ? string_ : nullptr;
        return true;
    }
    bool put(pv::Prim t, const void* data, uint32_t n) override {
        if (!ch_ || !ch_->connected() || !ch_->write_access()) return false;
        return ch_->put_raw(t, data, n);
    }
    bool put_notify(pv::Prim t, const void* data, uint32_t n, std::function<void(bool)> done) override {
        if (!ch_ || !ch_->connected() || !ch_->write_access()) return false;
        // The completion may come after the link was released (relinked, record removed): dropped.
        return ch_->put_raw(t, data, n, [gone = released_flag_, done = std::move(done)](const Result& r) {
            if (!*gone) done(r.ok());
        });
    }
    bool connected() const override { return ch_ && ch_->connected(); }
    pv::Prim type() const override {
        if (have_) return last_.prim;
        return ch_ && ch_->connected() ? ch_->native_type() : pv::Prim::Double;
    }
    void release() override {
        released_ = true;
        *released_flag_ = true;
        str_mon_.reset();
        mon_.reset();
        ch_.reset();
    }
    std::string describe() const override {
        return SB() << "CA link to " << name_ << " (" << (connected() ? "connected to " + ch_->server() : "disconnected")
                    << ")";
    }
    bool released() const { return released_; }
    void detach() {
        have_ = false;
        have_string_ = false;
        str_mon_.reset();
        mon_.reset();
        ch_.reset();
    }

private:
    void scan_if_cp() {
        if (proc_ == pv::Link::kCp || (proc_ == pv::Link::kCpp && rec_.scan == 0)) db_.scan_once(rec_);
    }

    pv::Database& db_;
    pv::Record& rec_;
    bool input_;
    uint8_t proc_;
    std::string name_;
    std::shared_ptr<Channel> ch_;
    std::shared_ptr<Monitor> mon_, str_mon_;
    ca::Value last_;
    char string_[pv::kStringSize] = {};
    bool have_ = false, have_string_ = false;
    bool released_ = false;
    std::shared_ptr<bool> released_flag_ = std::make_shared<bool>(false); // for late completions
};

CaLinks::CaLinks(pv::Database& db, ClientConfig cfg) : CaLinks(db) { cfg_ = std::move(cfg); }

CaLinks::CaLinks(pv::Database& db) : db_(db) {
    db_.set_remote_binder([this](pv::Record& r, const pv::FieldDesc& f, pv::Link& l, std::string* why) {
        return bind(r, f, l, why);
    });
}

void CaLinks::make_client() {
    if (client_) return;
    if (!cfg_) cfg_ = ClientConfig::from_env();
    client_ = std::make_unique<Client>(*loop_, *cfg_);
}

CaLinks::~CaLinks() {
    db_.set_remote_binder({});
    for (auto& l : links_) l->release();
}

pv::RemoteLink* CaLinks::bind(pv::Record& r, const pv::FieldDesc& f, pv::Link& l, std::string* why) {
    (void)why;
    const pv::LinkSpec& s = l.s();
    std::string name = s.field.empty() ? s.record : s.record + "." + s.field;
    // Released links are dropped here, so a record whose link is put again and again stays bounded.
    links_.erase(std::remove_if(links_.begin(), links_.end(), [](const auto& x) { return x->released(); }),
                 links_.end());
    links_.push_back(std::make_unique<Link>(db_, r, f, l.proc, name));
    Link* link = links_.back().get();
    if (loop_) {
        make_client();
        link->attach(*client_);
    }
    return link;
}

void CaLinks::start(EventLoop& loop) {
    loop_ = &loop;
    if (links_.empty()) return;
    make_client();
    for (auto& l : links_) l->attach(*client_);
}

void CaLinks::stop() {
    for (auto& l : links_) l->detach();
    client_.reset();
    loop_ = nullptr;
}

std::size_t CaLinks::size() const {
    return std::size_t(std::count_if(links_.begin(), links_.end(), [](const auto& l) { return !l->released(); }));
}

std::size_t CaLinks::connected_count() const {
    return std::size_t(
        std::count_if(links_.begin(), links_.end(), [](const auto& l) { return !l->released() && l->connected(); }));
}

} // namespace beamctl::ca
