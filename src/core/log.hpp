// Named loggers. Levels come from one environment variable, BEAMCTL_LOG, e.g.
//   BEAMCTL_LOG=info            (all loggers)      BEAMCTL_LOG=warn,ca=debug,ca.circuit=trace
// A key names a logger or a dotted prefix of one (`ca` covers `ca.server` and `ca.circuit`).
// A logger's level is checked before any formatting (LOG_DEBUG(log, "x=" << x) costs one compare
// when disabled). Thread-safe; never call from the RT cycle (RT code queues events instead).
#pragma once

#include <atomic>
#include <sstream>
#include <string>
#include <vector>

namespace beamctl::log {

enum class Level : int { trace = 0, debug, info, warn, err, off };

class Logger {
public:
    explicit Logger(const char* name);
    bool enabled(Level l) const { return int(l) >= level_.load(std::memory_order_relaxed); }
    void write(Level l, const std::string& msg) const;
    const std::string& name() const { return name_; }
    void set_level(Level l) { level_.store(int(l), std::memory_order_relaxed); }

private:
    std::string name_;
    std::atomic<int> level_;
};

// Re-reads BEAMCTL_LOG (or `spec` when given) and applies it to every logger.
void configure(const char* spec = nullptr);
// Checks BEAMCTL_LOG (or `spec` when given) against the level names and the loggers registered so
// far; loggers are static objects, so call it after static initialisation (first thing in main).
// Throws Error naming the bad item and listing the valid levels or the known loggers.
void validate(const char* spec = nullptr);
// Names of the registered loggers, sorted and without duplicates.
std::vector<std::string> logger_names();
// Rate limiter for logging bad input: true at most `per_s` times per second per limiter.
class RateLimit {
public:
    explicit RateLimit(int per_s = 5) : per_s_(per_s) {}
    bool allow();
    unsigned long suppressed() const { return suppressed_; }

private:
    int per_s_;
    long window_s_ = -1;
    int in_window_ = 0;
    unsigned long suppressed_ = 0;
};

} // namespace beamctl::log

#define BEAMCTL_LOG_AT(lg, lvl, expr)                                                              \
    do {                                                                                           \
        if ((lg).enabled(lvl)) {                                                                   \
            std::ostringstream beamctl_log_os_;                                                    \
            beamctl_log_os_ << expr;                                                               \
            (lg).write(lvl, beamctl_log_os_.str());                                                \
        }                                                                                          \
    } while (0)
#define LOG_TRACE(lg, expr) BEAMCTL_LOG_AT(lg, ::beamctl::log::Level::trace, expr)
#define LOG_DEBUG(lg, expr) BEAMCTL_LOG_AT(lg, ::beamctl::log::Level::debug, expr)
#define LOG_INFO(lg, expr) BEAMCTL_LOG_AT(lg, ::beamctl::log::Level::info, expr)
#define LOG_WARN(lg, expr) BEAMCTL_LOG_AT(lg, ::beamctl::log::Level::warn, expr)
#define LOG_ERR(lg, expr) BEAMCTL_LOG_AT(lg, ::beamctl::log::Level::err, expr)
