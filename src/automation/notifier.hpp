// Notification in the spirit of seed 003's alarm tool (LCLS's EASE): when a state machine latches
// or a PV of this IOC reaches an alarm severity, tell the configured people by email (SMTP to a
// configured server) and by webhook (HTTP POST of JSON). Rate-limited per rule, de-duplicated
// (the same text within `dedup_s` is sent once), retried, and logged (every delivery and every
// failure, served as PVs). Delivery runs on its own thread with time-outs: a slow or dead mail
// server never blocks control.
// Threading: notify()/poll()/counters on the IOC loop; delivery on the notifier's thread.
#pragma once

#include "config/ioc_config.hpp"
#include "pv/database.hpp"

#include <atomic>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace beamctl::automation {

class Notifier {
public:
    // Loads its records ($(P)notify:Sent, Failed, Suppressed, LastMessage, LastError) into `db`.
    Notifier(const config::NotifyEntry& cfg, const std::string& prefix, pv::Database& db, std::function<double()> clock);
    ~Notifier(); // stops the thread (what is queued and not sent is logged as not sent)
    Notifier(const Notifier&) = delete;
    Notifier& operator=(const Notifier&) = delete;

    // After init_records: the PV rules' records (Error naming the rule when one is not here), and
    // the delivery thread.
    void start();
    // A state machine latched (StateMachines::on_latch).
    void latched(const std::string& machine, const std::string& error);
    // The IOC loop: PV rules' severities, the delivery results into the PVs.
    void poll();

    uint64_t sent() const { return sent_; }
    uint64_t failed() const { return failed_; }
    uint64_t suppressed() const { return suppressed_; }

private:
    struct Message {
        std::string subject, body, json;
        int attempts = 0;
        std::vector<bool> delivered; // per channel (email, webhooks)
        double not_before = 0; // [s, steady clock] when a retry may go
    };
    struct Rule {
        config::NotifyEntry::Rule cfg;
        pv::Record* record = nullptr;
        int last_sevr = 0;
        double last_sent = -1e300;
    };
    void raise(Rule* rule, const std::string& subject, const std::string& body);
    void worker();
    bool deliver(Message& m, std::string& why); // to every channel not yet delivered; false: one failed

    config::NotifyEntry cfg_;
    std::string p_; // $(P)notify:
    pv::Database& db_;
    std::function<double()> clock_;
    std::vector<Rule> rules_;
    std::vector<std::pair<std::string, double>> recent_; // de-duplication: text, when
    uint64_t suppressed_ = 0;
    // shared with the thread
    std::mutex mu_;
    std::condition_variable cv_;
    std::deque<Message> queue_;
    std::vector<std::string> results_; // delivery log lines for the IOC loop
    bool stop_ = false;
    std::atomic<uint64_t> sent_{0}, failed_{0};
    std::thread thread_;
    uint64_t shown_sent_ = ~0ull, shown_failed_ = ~0ull, shown_suppressed_ = ~0ull;
};

} // namespace beamctl::automation
