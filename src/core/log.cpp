#include "core/log.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <mutex>
#include <vector>

namespace beamctl::log {
namespace {

struct Registry {
    std::mutex mu;
    std::vector<Logger*> loggers;
    std::string spec;
    bool spec_loaded = false;
};

Registry& registry() {
    static Registry r;
    return r;
}

const char* const kLevelNames[] = {"trace", "debug", "info", "warn", "error", "off"};

bool parse_level(const std::string& s, Level& out) {
    const auto& names = kLevelNames;
    for (int i = 0; i < 6; ++i)
        if (s == names[i]) {
            out = Level(i);
            return true;
        }
    if (s == "err") {
        out = Level::err;
        return true;
    }
    return false;
}

// Level for `name` from a spec like "warn,ca=debug,ca.circuit=trace"; the longest matching
// dotted prefix wins, a bare level sets the default.
Level level_for(const std::string& spec, const std::string& name) {
    Level def = Level::info, best = Level::info;
    size_t best_len = 0;
    bool have_best = false;
    size_t pos = 0;
    while (pos <= spec.size()) {
        size_t end = spec.find(',', pos);
        if (end == std::string::npos) end = spec.size();
        std::string item = spec.substr(pos, end - pos);
        pos = end + 1;
        if (item.empty()) continue;
        size_t eq = item.find('=');
        Level l;
        if (eq == std::string::npos) {
            if (parse_level(item, l)) def = l;
            continue;
        }
        std::string key = item.substr(0, eq);
        if (!parse_level(item.substr(eq + 1), l)) continue;
        bool match = name == key || (name.size() > key.size() && name.compare(0, key.size(), key) == 0 &&
                                     name[key.size()] == '.');
        if (match && key.size() >= best_len) {
            best = l;
            best_len = key.size();
            have_best = true;
        }
    }
    return have_best ? best : def;
}

const char* level_name(Level l) { return kLevelNames[int(l)]; }

std::string level_list() {
    std::string s;
    for (const char* n : kLevelNames) s += s.empty() ? n : std::string(" ") + n;
    return s + " (err = error)";
}

} // namespace

Logger::Logger(const char* name) : name_(name), level_(int(Level::info)) {
    auto& r = registry();
    std::lock_guard<std::mutex> g(r.mu);
    if (!r.spec_loaded) {
        const char* env = std::getenv("BEAMCTL_LOG");
        r.spec = env ? env : "";
        r.spec_loaded = true;
    }
    level_.store(int(level_for(r.spec, name_)));
    r.loggers.push_back(this);
}

void Logger::write(Level l, const std::string& msg) const {
    auto now = std::chrono::system_clock::now();
    auto t = std::chrono::system_clock::to_time_t(now);
    auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
    std::tm tm{};
    gmtime_r(&t, &tm);
    char ts[32];
    std::strftime(ts, sizeof ts, "%Y-%m-%dT%H:%M:%S", &tm);
    std::fprintf(stderr, "%s.%03dZ %-5s %s: %s\n", ts, int(ms), level_name(l), name_.c_str(),
                 msg.c_str());
}

void configure(const char* spec) {
    auto& r = registry();
    std::lock_guard<std::mutex> g(r.mu);
    const char* env = spec ? spec : std::getenv("BEAMCTL_LOG");
    r.spec = env ? env : "";
    r.spec_loaded = true;
    for (Logger* lg : r.loggers) lg->set_level(level_for(r.spec, lg->name()));
}

std::vector<std::string> logger_names() {
    auto& r = registry();
    std::vector<std::string> names;
    {
        std::lock_guard<std::mutex> g(r.mu);
        for (const Logger* lg : r.loggers) names.push_back(lg->name());
    }
    std::sort(names.begin(), names.end());
    names.erase(std::unique(names.begin(), names.end()), names.end());
    return names;
}

void validate(const char* spec) {
    const char* env = spec ? spec : std::getenv("BEAMCTL_LOG");
    std::string text = env ? env : "";
    std::vector<std::string> names = logger_names();
    auto known = [&](const std::string& key) {
        for (const auto& n : names)
            if (n == key || (n.size() > key.size() && n.compare(0, key.size(), key) == 0 && n[key.size()] == '.'))
                return true;
        return false;
    };
    auto known_list = [&] {
        std::string s;
        for (const auto& n : names) s += s.empty() ? n : " " + n;
        return s;
    };
    const char* what = spec ? "log spec" : "BEAMCTL_LOG";
    size_t pos = 0;
    while (pos <= text.size()) {
        size_t end = text.find(',', pos);
        if (end == std::string::npos) end = text.size();
        std::string item = text.substr(pos, end - pos);
        pos = end + 1;
        if (item.empty()) continue;
        size_t eq = item.find('=');
        std::string level = eq == std::string::npos ? item : item.substr(eq + 1);
        Level l;
        if (!parse_level(level, l))
            throw Error(SB() << what << "='" << text << "': unknown level '" << level << "' in '" << item
                             << "'; levels: " << level_list());
        if (eq == std::string::npos) continue;
        std::string key = item.substr(0, eq);
        if (key.empty())
            throw Error(SB() << what << "='" << text << "': no logger name before '=' in '" << item
                             << "'; known loggers (or a dotted prefix of one): " << known_list());
        if (!known(key))
            throw Error(SB() << what << "='" << text << "': unknown logger '" << key << "' in '" << item
                             << "'; known loggers (or a dotted prefix of one): " << known_list());
    }
}

bool RateLimit::allow() {
    long now_s = long(std::time(nullptr));
    if (now_s != window_s_) {
        window_s_ = now_s;
        in_window_ = 0;
    }
    if (in_window_ < per_s_) {
        ++in_window_;
        return true;
    }
    ++suppressed_;
    return false;
}

} // namespace beamctl::log
