// Notification by email and webhook (see notifier.hpp).
#include "automation/notifier.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "pv/db_file.hpp"
#include "pv/publish.hpp"

#include <netdb.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <ctime>

namespace beamctl::automation {

namespace {

log::Logger lg("notify");

double steady_s() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

std::string utc(const char* format) {
    const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    std::tm tm{};
    gmtime_r(&t, &tm);
    char b[64];
    std::strftime(b, sizeof b, format, &tm);
    return b;
}

std::string json_string(const std::string& s) {
    std::string o = "\"";
    for (unsigned char c : s) {
        if (c == '"' || c == '\\') o += '\\', o += char(c);
        else if (c == '\n') o += "\\n";
        else if (c < 0x20) {
            char b[8];
            std::snprintf(b, sizeof b, "\\u%04x", c);
            o += b;
        } else o += char(c);
    }
    return o + "\"";
}

// A blocking TCP connection with time-outs on every operation (the notifier's thread only).
class Conn {
public:
    Conn(const std::string& host, int port, double timeout_s, std::string& why) {
        addrinfo hints{}, *res = nullptr;
        hints.ai_socktype = SOCK_STREAM;
        if (int rc = getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &res); rc != 0) {
            why = "cannot resolve " + host + ": " + gai_strerror(rc);
            return;
        }
        timeval tv{};
        tv.tv_sec = long(timeout_s), tv.tv_usec = long((timeout_s - double(tv.tv_sec)) * 1e6);
        for (addrinfo* a = res; a && fd_ < 0; a = a->ai_next) {
            int fd = ::socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol);
            if (fd < 0) continue;
            setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
            setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
            if (::connect(fd, a->ai_addr, a->ai_addrlen) == 0) fd_ = fd;
            else ::close(fd);
        }
        freeaddrinfo(res);
        if (fd_ < 0) why = "cannot connect to " + host + ":" + std::to_string(port) + ": " + std::strerror(errno);
    }
    ~Conn() {
        if (fd_ >= 0) ::close(fd_);
    }
    bool ok() const { return fd_ >= 0; }
    bool send(const std::string& s) {
        for (std::size_t off = 0; off < s.size();) {
            const ssize_t n = ::send(fd_, s.data() + off, s.size() - off, MSG_NOSIGNAL);
            if (n <= 0) return false;
            off += std::size_t(n);
        }
        return true;
    }
    // One line (without CR LF); false on time-out or close.
    bool line(std::string& out) {
        out.clear();
        for (;;) {
            const std::size_t nl = buf_.find("\r\n");
            if (nl != std::string::npos) {
                out = buf_.substr(0, nl);
                buf_.erase(0, nl + 2);
                return true;
            }
            if (buf_.size() > 65536) return false;
            char b[1024];
            const ssize_t n = ::recv(fd_, b, sizeof b, 0);
            if (n <= 0) return false;
            buf_.append(b, std::size_t(n));
        }
    }

private:
    int fd_ = -1;
    std::string buf_;
};

// An SMTP reply (multi-line: "250-..." then "250 ..."); true when its code is `want` (or 251 for 250).
bool smtp_reply(Conn& c, int want, std::string& last) {
    std::string l;
    do {
        if (!c.line(l)) {
            last = "no reply";
            return false;
        }
    } while (l.size() > 3 && l[3] == '-');
    last = l;
    const int code = std::atoi(l.c_str());
    return code == want || (want == 250 && code == 251);
}

bool send_mail(const config::NotifyEntry& cfg, const std::string& subject, const std::string& body, std::string& why) {
    Conn c(cfg.smtp_host, cfg.smtp_port, cfg.timeout_s, why);
    if (!c.ok()) return false;
    std::string r;
    auto step = [&](const std::string& cmd, int want) {
        if (!cmd.empty() && !c.send(cmd + "\r\n")) return why = "SMTP: sending " + cmd.substr(0, 10) + " failed", false;
        if (!smtp_reply(c, want, r)) return why = "SMTP: " + (cmd.empty() ? std::string("greeting") : cmd.substr(0, 20)) + ": " + r, false;
        return true;
    };
    if (!step("", 220) || !step("EHLO beamctl", 250) || !step("MAIL FROM:<" + cfg.from + ">", 250)) return false;
    for (const std::string& to : cfg.to)
        if (!step("RCPT TO:<" + to + ">", 250)) return false;
    if (!step("DATA", 354)) return false;
    std::string msg = "From: " + cfg.from + "\r\nTo: ";
    for (std::size_t i = 0; i < cfg.to.size(); ++i) msg += (i ? ", " : "") + cfg.to[i];
    msg += "\r\nSubject: " + subject + "\r\nDate: " + utc("%a, %d %b %Y %H:%M:%S +0000") +
           "\r\nContent-Type: text/plain; charset=utf-8\r\n\r\n";
    std::size_t at = 0; // the body, dot-stuffed, CR LF line ends
    while (at <= body.size()) {
        const std::size_t nl = body.find('\n', at);
        std::string l = body.substr(at, nl == std::string::npos ? std::string::npos : nl - at);
        if (!l.empty() && l[0] == '.') l = "." + l;
        msg += l + "\r\n";
        if (nl == std::string::npos) break;
        at = nl + 1;
    }
    msg += ".";
    if (!step(msg, 250)) return false;
    step("QUIT", 221);
    return true;
}

bool post_json(const config::NotifyEntry::Webhook& h, double timeout_s, const std::string& json, std::string& why) {
    Conn c(h.host, h.port, timeout_s, why);
    if (!c.ok()) return false;
    const std::string req = "POST " + h.path + " HTTP/1.1\r\nHost: " + h.host + ":" + std::to_string(h.port) +
                            "\r\nContent-Type: application/json\r\nContent-Length: " + std::to_string(json.size()) +
                            "\r\nConnection: close\r\n\r\n" + json;
    std::string status;
    if (!c.send(req) || !c.line(status)) return why = "webhook " + h.url + ": no reply", false;
    // "HTTP/1.1 204 No Content"
    const std::size_t sp = status.find(' ');
    const int code = sp == std::string::npos ? 0 : std::atoi(status.c_str() + sp + 1);
    if (code < 200 || code > 299) return why = "webhook " + h.url + ": " + status, false;
    return true;
}

} // namespace

Notifier::Notifier(const config::NotifyEntry& cfg, const std::string& prefix, pv::Database& db, std::function<double()> clock)
    : cfg_(cfg), p_(prefix + "notify:"), db_(db), clock_(std::move(clock)) {
    for (const auto& r : cfg_.rules) rules_.push_back(Rule{r});
    pv::DbFile f;
    for (const char* r : {"Sent", "Failed", "Suppressed"}) f.records.push_back(pv::generated_record("longin", p_ + r, {}));
    for (const char* r : {"LastMessage", "LastError"})
        f.records.push_back(pv::generated_record("waveform", p_ + r, {{"FTVL", "CHAR"}, {"NELM", "512"}}));
    db_.load(f);
}

Notifier::~Notifier() {
    {
        std::lock_guard<std::mutex> lk(mu_);
        stop_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
    for (const Message& m : queue_) LOG_WARN(lg, "not sent (the IOC stopped): " << m.subject);
}

void Notifier::start() {
    // The delivery thread starts here, not in the constructor: the IOC blocks SIGTERM/SIGINT in
    // every thread before it brings the engine up (Ioc::run), and a thread made earlier would take
    // a stop signal's default action (killing the process without its safe stop).
    if (!thread_.joinable()) thread_ = std::thread([this] { worker(); });
    for (Rule& r : rules_) {
        if (r.cfg.pv.empty()) continue;
        r.record = db_.find(r.cfg.pv.substr(0, r.cfg.pv.find('.')));
        if (!r.record) throw Error(r.cfg.where + ": notify: '" + r.cfg.pv + "' is not a record of this IOC");
        r.last_sevr = r.record->sevr;
    }
    LOG_INFO(lg, rules_.size() << " rule(s); email " << (cfg_.smtp_host.empty() ? std::string("none") : "via " + cfg_.smtp_host) << ", "
                               << cfg_.webhooks.size() << " webhook(s)");
}

void Notifier::raise(Rule* rule, const std::string& subject, const std::string& body) {
    const double now = clock_();
    const std::string text = subject + "\n" + body;
    for (auto it = recent_.begin(); it != recent_.end();) it = now - it->second > cfg_.dedup_s ? recent_.erase(it) : it + 1;
    for (const auto& [t, when] : recent_)
        if (t == text) {
            ++suppressed_;
            LOG_INFO(lg, "suppressed (the same within " << cfg_.dedup_s << " s): " << subject);
            return;
        }
    if (rule && now - rule->last_sent < cfg_.min_interval_s) {
        ++suppressed_;
        LOG_INFO(lg, "suppressed (at most one per " << cfg_.min_interval_s << " s for " << rule->cfg.where << "): " << subject);
        return;
    }
    if (rule) rule->last_sent = now;
    recent_.emplace_back(text, now);
    Message m;
    m.subject = subject, m.body = body;
    m.json = "{\"subject\": " + json_string(subject) + ", \"text\": " + json_string(body) + ", \"time\": " +
             json_string(utc("%Y-%m-%dT%H:%M:%SZ")) + "}";
    {
        std::lock_guard<std::mutex> lk(mu_);
        queue_.push_back(std::move(m));
    }
    cv_.notify_all();
    pv::set_text(db_, *db_.find(p_ + "LastMessage"), subject);
}

void Notifier::latched(const std::string& machine, const std::string& error) {
    for (Rule& r : rules_)
        if (r.cfg.state_machine == machine || r.cfg.state_machine == "*")
            return raise(&r, "[beamctl] state machine " + machine + " latched",
                         "State machine " + machine + " is in its error latch:\n" + error +
                             "\n\nAcknowledge with its Ack PV once the cause is understood.");
}

void Notifier::poll() {
    static const char* kSevr[] = {"NO_ALARM", "MINOR", "MAJOR", "INVALID"};
    for (Rule& r : rules_) {
        if (!r.record) continue;
        const int sevr = r.record->sevr;
        if (sevr >= r.cfg.severity && r.last_sevr < r.cfg.severity) {
            double v = pv::get_value(*r.record);
            char b[40];
            std::snprintf(b, sizeof b, "%g", v);
            raise(&r, "[beamctl] " + r.cfg.pv + " in " + kSevr[std::min(sevr, 3)] + " alarm",
                  r.cfg.pv + " = " + b + ", severity " + kSevr[std::min(sevr, 3)] + " (rule: at least " + kSevr[r.cfg.severity] + ").");
        }
        r.last_sevr = sevr;
    }
    std::vector<std::string> results;
    {
        std::lock_guard<std::mutex> lk(mu_);
        results.swap(results_);
    }
    if (!results.empty()) pv::set_text(db_, *db_.find(p_ + "LastError"), results.back());
    auto show = [&](const char* name, uint64_t v, uint64_t& shown) {
        if (v != shown) shown = v, pv::set_value(db_, *db_.find(p_ + name), double(v), false);
    };
    show("Sent", sent_, shown_sent_);
    show("Failed", failed_, shown_failed_);
    show("Suppressed", suppressed_, shown_suppressed_);
}

bool Notifier::deliver(Message& m, std::string& why) {
    // channel 0: email, 1..: the webhooks; a retry goes only to those that failed
    m.delivered.resize(1 + cfg_.webhooks.size(), false);
    if (cfg_.smtp_host.empty()) m.delivered[0] = true;
    for (std::size_t k = 0; k < m.delivered.size(); ++k) {
        if (m.delivered[k]) continue;
        std::string w;
        m.delivered[k] = k == 0 ? send_mail(cfg_, m.subject, m.body, w) : post_json(cfg_.webhooks[k - 1], cfg_.timeout_s, m.json, w);
        if (!m.delivered[k]) why += (why.empty() ? "" : "; ") + w;
    }
    return why.empty();
}

void Notifier::worker() {
    std::unique_lock<std::mutex> lk(mu_);
    for (;;) {
        if (stop_) return;
        if (queue_.empty()) {
            cv_.wait(lk);
            continue;
        }
        const double now = steady_s();
        if (queue_.front().not_before > now) {
            cv_.wait_for(lk, std::chrono::duration<double>(queue_.front().not_before - now));
            continue;
        }
        Message m = std::move(queue_.front());
        queue_.pop_front();
        lk.unlock();
        std::string why;
        const bool ok = deliver(m, why);
        ++m.attempts;
        lk.lock();
        if (ok) {
            ++sent_;
            LOG_INFO(lg, "sent: " << m.subject);
        } else if (m.attempts <= cfg_.retries) {
            LOG_WARN(lg, "not delivered (attempt " << m.attempts << ", retrying in " << cfg_.retry_interval_s << " s): " << why);
            results_.push_back("attempt " + std::to_string(m.attempts) + ": " + why);
            m.not_before = steady_s() + cfg_.retry_interval_s;
            queue_.push_back(std::move(m));
        } else {
            ++failed_;
            LOG_ERR(lg, "not delivered after " << m.attempts << " attempts, given up: " << m.subject << ": " << why);
            results_.push_back("given up after " + std::to_string(m.attempts) + " attempts: " + why);
        }
    }
}

} // namespace beamctl::automation
