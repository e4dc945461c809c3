// Channel Access links of a PV database, as EPICS dbCa: a link with CA, CP or CPP that names a
// record of another server becomes a channel of one ca::Client. An input link reads the last
// value its monitor (DBR_TIME_<native>, DBE_VALUE|DBE_ALARM) received, with that value's alarm
// for MS/MSS/MSI; CP processes the record on every update and on disconnection (CPP only a
// Passive record); while disconnected a read raises LINK/INVALID. An output link writes with a
// put (WRITE, not waited for; processing follows the other server's field rules); a forward
// link "rec.PROC CA" writes 1 to it.
// Threading: everything runs on the thread of the loop given to start(), which owns the database.
#pragma once

#include "ca/client.hpp"
#include "pv/database.hpp"

#include <memory>
#include <optional>
#include <vector>

namespace beamctl::ca {

class CaLinks {
public:
    // Installs itself as db's remote binder (before Database::init_records). The client is made
    // only once a CA link exists, from `cfg`.
    CaLinks(pv::Database& db, ClientConfig cfg);
    // As above with ClientConfig::from_env(), read when the first CA link needs the client (so
    // a database without CA links never reads EPICS_CA_*).
    explicit CaLinks(pv::Database& db);
    ~CaLinks();
    CaLinks(const CaLinks&) = delete;
    CaLinks& operator=(const CaLinks&) = delete;

    // Connects the links on `loop`: those bound so far now, later ones when they are bound.
    void start(EventLoop& loop);
    // Closes the client before its loop goes away: the links read as disconnected until the
    // next start().
    void stop();
    std::size_t size() const;           // links in use
    std::size_t connected_count() const;
    const Client* client() const { return client_.get(); }

private:
    class Link;
    pv::RemoteLink* bind(pv::Record& r, const pv::FieldDesc& f, pv::Link& l, std::string* why);
    void make_client();

    pv::Database& db_;
    std::optional<ClientConfig> cfg_; // empty: from the environment
    EventLoop* loop_ = nullptr;
    std::unique_ptr<Client> client_;
    std::vector<std::unique_ptr<Link>> links_;
};

} // namespace beamctl::ca
