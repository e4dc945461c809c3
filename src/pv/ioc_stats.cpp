#include "pv/ioc_stats.hpp"

#include "pv/database.hpp"
#include "pv/record.hpp"
#include "pv/sub_routines.hpp"

#include <dirent.h>
#include <sys/resource.h>
#include <sys/utsname.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>

namespace beamctl::pv {

namespace {

std::string g_release = "beamctl, EPICS 7.0.8 records";

// devIocStats's ai parameters (devIocStatsAnalog.c) and the group each is sampled with. Those
// Linux has no source for read 0 there too (blocks, workspace, mbufs, interface errors).
struct NumParam {
    const char* name;
    IocStats::Group group;
};
enum : int {
    kParamFreeBytes, kParamFreeBlocks, kParamMaxFree, kParamAllocBytes, kParamAllocBlocks, kParamTotalBytes, kParamWsAllocBytes, kParamWsFreeBytes,
    kParamWsTotalBytes, kParamSysLoad, kParamIocLoad, kParamCpuCompat, kParamCpus, kParamSuspended, kParamFd, kParamMaxFd, kParamCaClients, kParamCaChannels,
    kParamMinDataMbuf, kParamMinSysMbuf, kParamDataMbuf, kParamSysMbuf, kParamInpErrs, kParamOutErrs, kParamRecords, kParamPid, kParamPpid, kParamZoneTemp,
};
constexpr NumParam kNumParams[] = {
    {"free_bytes", IocStats::kMemory},       {"free_blocks", IocStats::kMemory},
    {"max_free", IocStats::kMemory},         {"allocated_bytes", IocStats::kMemory},
    {"allocated_blocks", IocStats::kMemory}, {"total_bytes", IocStats::kMemory},
    {"workspace_alloc_bytes", IocStats::kMemory}, {"workspace_free_bytes", IocStats::kMemory},
    {"workspace_total_bytes", IocStats::kMemory}, {"sys_cpuload", IocStats::kLoad},
    {"ioc_cpuload", IocStats::kLoad},        {"cpu", IocStats::kLoad},
    {"no_of_cpus", IocStats::kLoad},         {"suspended_tasks", IocStats::kLoad},
    {"fd", IocStats::kFd},                   {"maxfd", IocStats::kFd},
    {"ca_clients", IocStats::kCa},           {"ca_connections", IocStats::kCa},
    {"min_data_mbuf", IocStats::kMemory},    {"min_sys_mbuf", IocStats::kMemory},
    {"data_mbuf", IocStats::kMemory},        {"sys_mbuf", IocStats::kMemory},
    {"inp_errs", IocStats::kMemory},         {"out_errs", IocStats::kMemory},
    {"records", IocStats::kStatic},          {"proc_id", IocStats::kStatic},
    {"parent_proc_id", IocStats::kStatic},   {"sys_zonetemp", IocStats::kLoad},
};
// The ao parameters: a group's sampling period [s], with devIocStats's defaults.
struct RateParam {
    const char* name;
    IocStats::Group group;
    double default_s;
};
constexpr RateParam kRateParams[] = {
    {"memory_scan_rate", IocStats::kMemory, 10.0},
    {"cpu_scan_rate", IocStats::kLoad, 20.0},
    {"fd_scan_rate", IocStats::kFd, 10.0},
    {"ca_scan_rate", IocStats::kCa, 15.0},
};
// The stringin/waveform parameters (devIocStatsString.c, devIocStatsWaveform.c).
constexpr const char* kTextParams[] = {
    "startup_script_1", "startup_script_2", "startup_script", "bootline_1", "bootline_2", "bootline_3",
    "bootline_4", "bootline_5", "bootline_6", "bsp_rev", "kernel_ver", "epics_ver", "engineer", "location",
    "up_time", "hostname", "pwd1", "pwd2", "pwd",
};
// base 7.0.8's EPICS environment parameters (envDefs.h) with their defaults (CONFIG_ENV,
// CONFIG_SITE_ENV): what "IOC epics var" reads when the environment does not set one.
struct EpicsParam {
    const char* name;
    const char* fallback;
};
constexpr EpicsParam kEpicsParams[] = {
    {"EPICS_CA_ADDR_LIST", ""},         {"EPICS_CA_CONN_TMO", "30.0"},
    {"EPICS_CA_AUTO_ADDR_LIST", "YES"}, {"EPICS_CA_REPEATER_PORT", "5065"},
    {"EPICS_CA_SERVER_PORT", "5064"},   {"EPICS_CA_MAX_ARRAY_BYTES", "16384"},
    {"EPICS_CA_AUTO_ARRAY_BYTES", "YES"}, {"EPICS_CA_MAX_SEARCH_PERIOD", "300.0"},
    {"EPICS_CA_NAME_SERVERS", ""},      {"EPICS_CA_MCAST_TTL", "1"},
    {"EPICS_CAS_INTF_ADDR_LIST", ""},   {"EPICS_CAS_IGNORE_ADDR_LIST", ""},
    {"EPICS_CAS_AUTO_BEACON_ADDR_LIST", ""}, {"EPICS_CAS_BEACON_ADDR_LIST", ""},
    {"EPICS_CAS_SERVER_PORT", ""},      {"EPICS_CA_BEACON_PERIOD", "15.0"},
    {"EPICS_CAS_BEACON_PERIOD", ""},    {"EPICS_CAS_BEACON_PORT", ""},
    {"EPICS_BUILD_COMPILER_CLASS", "gcc"}, {"EPICS_BUILD_OS_CLASS", "Linux"},
    {"EPICS_BUILD_TARGET_ARCH", "linux-x86_64"}, {"EPICS_TZ", "CST6CDT,M3.2.0/2,M11.1.0/2"},
    {"EPICS_TS_NTP_INET", ""},          {"EPICS_IOC_IGNORE_SERVERS", ""},
    {"EPICS_IOC_LOG_PORT", "7004"},     {"EPICS_IOC_LOG_INET", ""},
    {"EPICS_IOC_LOG_FILE_LIMIT", "1000000"}, {"EPICS_IOC_LOG_FILE_NAME", ""},
    {"EPICS_IOC_LOG_FILE_COMMAND", ""}, {"IOCSH_PS1", "epics> "},
    {"IOCSH_HISTSIZE", "50"},           {"IOCSH_HISTEDIT_DISABLE", ""},
};

template <typename T, std::size_t N, typename Name> int find_param(const T (&table)[N], std::string_view p, Name name) {
    for (std::size_t i = 0; i < N; ++i)
        if (p == name(table[i])) return int(i);
    return -1;
}

const char* env_or(const char* name, const char* fallback) {
    const char* v = std::getenv(name);
    return v ? v : fallback;
}

// devIocStats's startup script: $(STARTUP)/$(ST_CMD) (IOCSH_STARTUP_SCRIPT when STARTUP is unset).
std::string startup_script() {
    const char* sp = std::getenv("STARTUP");
    if (!sp) sp = std::getenv("IOCSH_STARTUP_SCRIPT");
    if (!sp) return "<not available>";
    std::string s = sp;
    if (const char* st = std::getenv("ST_CMD"); st && *st) s += std::string("/") + st;
    return s;
}

std::string working_directory() {
    char buf[4096];
    return ::getcwd(buf, sizeof buf) ? std::string(buf) : std::string("<not available>");
}

std::string kernel_version() {
    utsname u{};
    if (::uname(&u) != 0) return "<not available>";
    return SB() << u.sysname << " " << u.release << " " << u.version;
}

std::string host_name() {
    char buf[256] = {};
    if (::gethostname(buf, sizeof buf - 1) != 0) return "<not available>";
    return buf;
}

// A part of a text that is longer than one DBR_STRING (39 characters each, as devIocStats cuts it).
std::string part(const std::string& s, int index) {
    std::size_t at = std::size_t(index) * (kStringSize - 1);
    return at >= s.size() ? std::string() : s.substr(at, kStringSize - 1);
}

// "1 day, 03:04:05" / "12 days, ..." / "00:00:07", as devIocStats's up_time.
std::string up_time(double seconds) {
    auto t = static_cast<unsigned long>(seconds > 0 ? seconds : 0);
    unsigned long secs = t % 60, mins = t / 60 % 60, hours = t / 3600 % 24, days = t / 86400;
    char buf[64];
    int n = 0;
    if (days == 1) n = std::snprintf(buf, sizeof buf, "1 day, ");
    else if (days > 1) n = std::snprintf(buf, sizeof buf, "%lu days, ", days);
    std::snprintf(buf + n, sizeof buf - std::size_t(n), "%02lu:%02lu:%02lu", hours, mins, secs);
    return buf;
}

double wall_s() {
    timespec ts{};
    ::clock_gettime(CLOCK_MONOTONIC, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

// Busy time of all CPUs (user + nice + system) [s], from /proc/stat's first line.
double system_busy_s() {
    std::FILE* f = std::fopen("/proc/stat", "r");
    if (!f) return 0;
    unsigned long long user = 0, nice = 0, sys = 0;
    int n = std::fscanf(f, "cpu %llu %llu %llu", &user, &nice, &sys);
    std::fclose(f);
    if (n != 3) return 0;
    return double(user + nice + sys) / double(::sysconf(_SC_CLK_TCK));
}

// This process's CPU time, user + system [s].
double process_cpu_s() {
    rusage u{};
    ::getrusage(RUSAGE_SELF, &u);
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + double(u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-6;
}

const auto g_start_wall_s = wall_s(); // up_time counts from program start

// ---- the subroutines of devIocStats's READACF and SYSRESET (base's asSubRecordFunctions.c and
// devIocStatsSub.c name them; built in, found by SNAM as a dlload-ed library's are)
std::function<bool()> g_reload_acf;
std::function<void()> g_restart;

long as_sub_init(beamctl_sub*) { return 0; }
long as_sub_process(beamctl_sub* s) { // a put of 1 re-reads the ACF; VAL reads 0 after
    if (s->val != 1.0) return 0;
    s->val = 0;
    if (!g_reload_acf) {
        std::fprintf(stderr, "%s: asSubProcess: this IOC has no access-security file to re-read\n", s->name);
        return -1;
    }
    return g_reload_acf() ? 0 : -1;
}
long reboot_proc(beamctl_sub* s) { // A..F all 0 and L 1: restart (a clean stop here)
    if (!(s->a < 0.5 && s->b < 0.5 && s->c < 0.5 && s->d < 0.5 && s->e < 0.5 && s->f < 0.5 && s->l > 0.5)) return 0;
    if (!g_restart) return -1;
    std::fprintf(stderr, "%s: IOC reboot started (beamctl: a clean stop)\n", s->name);
    g_restart();
    return 0;
}

} // namespace

void add_builtin_routines(RecordRoutines& routines) {
    routines.add({"asSubInit", as_sub_init, nullptr, ""});
    routines.add({"asSubProcess", as_sub_process, nullptr, ""});
    routines.add({"rebootProc", reboot_proc, nullptr, ""});
}

// One record's link to a devIocStats parameter.
class IocStats::Device : public LinkDevice {
public:
    enum class Kind : uint8_t { Number, Rate, Text, EnvVar, EpicsVar, Bad };
    Device(IocStats& s, Kind k, int param, std::string arg, Record* r)
        : stats_(s), kind_(k), param_(param), arg_(std::move(arg)), rec_(r) {}

    bool read(double& v) override {
        if (kind_ == Kind::Number) {
            v = stats_.value(param_);
            return true;
        }
        if (kind_ == Kind::Rate) {
            v = stats_.period_s_[kRateParams[param_].group];
            return true;
        }
        return false;
    }
    uint16_t read_alarm() const override { return kind_ == Kind::EpicsVar ? kStatUdf : kStatLink; }
    bool is_text() const override { return kind_ == Kind::Text || kind_ == Kind::EnvVar || kind_ == Kind::EpicsVar; }
    bool read_text(std::string& out) override {
        switch (kind_) {
        case Kind::EnvVar: out = env_or(arg_.c_str(), "<not available>"); return true;
        case Kind::EpicsVar:
            if (param_ < 0) { // not one of base's: devIocStats reads "<undefined>" with a UDF alarm
                out = "<undefined>";
                return false;
            }
            out = env_or(kEpicsParams[param_].name, kEpicsParams[param_].fallback);
            return true;
        case Kind::Text: out = stats_text(); return true;
        default: return false;
        }
    }
    bool write(double v) override {
        if (kind_ != Kind::Rate) return false;
        if (v > 0 && std::isfinite(v)) { // devIocStats keeps the period it has for a value <= 0
            Group g = kRateParams[param_].group;
            stats_.period_s_[g] = v;
            stats_.next_s_[g] = 0; // the next tick samples and starts the new period
        }
        return true;
    }
    std::string describe() const override {
        switch (kind_) {
        case Kind::Number: return SB() << "IOC stats " << kNumParams[param_].name;
        case Kind::Rate: return SB() << "IOC stats " << kRateParams[param_].name << " (" << stats_.period_s_[kRateParams[param_].group] << " s)";
        case Kind::Text: return SB() << "IOC stats " << arg_;
        case Kind::EnvVar: return SB() << "IOC env var " << arg_;
        case Kind::EpicsVar: return SB() << "IOC epics var " << arg_;
        case Kind::Bad: return SB() << "IOC stats: no parameter '" << arg_ << "'";
        }
        return {};
    }
    void release() override { rec_ = nullptr; }

    Record* record() const { return rec_; }
    Group group() const {
        if (kind_ == Kind::Number) return kNumParams[param_].group;
        return kStatic;
    }

private:
    std::string stats_text() const {
        const std::string& p = arg_;
        if (p == "startup_script_1") return part(startup_script(), 0);
        if (p == "startup_script_2") return part(startup_script(), 1);
        if (p == "startup_script") return startup_script();
        if (p.rfind("bootline_", 0) == 0 || p == "bsp_rev") return ""; // no boot line on Linux
        if (p == "kernel_ver") return part(kernel_version(), 0);
        if (p == "epics_ver") return g_release;
        if (p == "engineer") {
            const char* e = std::getenv("ENGINEER");
            if (!e) e = std::getenv("LOGNAME");
            if (!e) e = std::getenv("USER");
            return part(e ? e : "<not available>", 0);
        }
        if (p == "location") return part(env_or("LOCATION", "<not available>"), 0);
        if (p == "up_time") return up_time(wall_s() - g_start_wall_s);
        if (p == "hostname") return part(host_name(), 0);
        if (p == "pwd1") return part(working_directory(), 0);
        if (p == "pwd2") return part(working_directory(), 1);
        if (p == "pwd") return working_directory();
        return "";
    }

    IocStats& stats_;
    Kind kind_;
    int param_;
    std::string arg_;
    Record* rec_;
};

IocStats::IocStats() {
    period_s_.fill(0);
    for (const RateParam& r : kRateParams) period_s_[r.group] = r.default_s;
    sample(kMemory, 0);
    sample(kLoad, 0);
    sample(kFd, 0);
}

IocStats::~IocStats() = default;

void IocStats::set_release(std::string text) { g_release = std::move(text); }

void IocStats::set_admin_hooks(std::function<bool()> reload_acf, std::function<void()> restart) {
    g_reload_acf = std::move(reload_acf);
    g_restart = std::move(restart);
}

LinkDevice* IocStats::bind(Record& r, const Link& l, uint16_t dtyp, std::string* why) {
    std::string p = l.kind == Link::Kind::Hw ? l.s().address : std::string();
    while (!p.empty() && (p.back() == ' ' || p.back() == '\t')) p.pop_back();
    std::string_view type = r.type().name();
    auto make = [&](Device::Kind k, int param) {
        devices_.push_back(std::make_unique<Device>(*this, k, param, p, &r));
        return devices_.back().get();
    };
    auto unknown = [&](const char* what) {
        // as devIocStats's init_record (recGblRecordError): the record loads and reads nothing
        r.init_error(SB() << "DTYP \"" << kMenuSoftDtyp.choices[dtyp] << "\": '" << p << "' is not " << what);
        return make(Device::Kind::Bad, -1);
    };
    auto name_of = [](const auto& e) { return std::string_view(e.name); };
    switch (dtyp) {
    case kDtypIocEnvVar: return make(Device::Kind::EnvVar, 0);
    case kDtypIocEpicsVar: {
        int i = find_param(kEpicsParams, p, name_of);
        if (i < 0) r.init_error(SB() << "DTYP \"IOC epics var\": '" << p << "' is not an EPICS environment parameter "
                                        "of base 7.0.8 (it reads \"<undefined>\" with a UDF alarm)");
        return make(Device::Kind::EpicsVar, i);
    }
    case kDtypIocStats: break;
    default:
        if (why) *why = "not an IOC stats device support";
        return nullptr;
    }
    if (type == "ai") {
        int i = find_param(kNumParams, p, name_of);
        return i < 0 ? unknown("one of devIocStats's ai parameters (free_bytes, ioc_cpuload, fd, ca_clients, ...)")
                     : make(Device::Kind::Number, i);
    }
    if (type == "ao") {
        int i = find_param(kRateParams, p, name_of);
        return i < 0 ? unknown("a scan rate (memory_scan_rate, cpu_scan_rate, fd_scan_rate or ca_scan_rate)")
                     : make(Device::Kind::Rate, i);
    }
    int i = find_param(kTextParams, p, [](const char* s) { return std::string_view(s); });
    return i < 0 ? unknown("one of devIocStats's text parameters (up_time, hostname, epics_ver, pwd1, ...)")
                 : make(Device::Kind::Text, i);
}

void IocStats::sample(Group g, double now_s) {
    switch (g) {
    case kMemory: { // /proc/self/statm's resident pages; /proc/meminfo's MemFree + Buffers + Cached
        unsigned long size = 0, resident = 0;
        if (std::FILE* f = std::fopen("/proc/self/statm", "r")) {
            if (std::fscanf(f, "%lu %lu", &size, &resident) != 2) resident = 0;
            std::fclose(f);
        }
        s_.mem_alloc = double(resident) * double(::sysconf(_SC_PAGESIZE));
        double total = 0, free = 0;
        if (std::FILE* f = std::fopen("/proc/meminfo", "r")) {
            char title[64];
            unsigned long kib = 0;
            while (std::fscanf(f, "%63s %lu %*[^\n]", title, &kib) == 2) {
                if (!std::strcmp(title, "MemTotal:")) total = double(kib) * 1024;
                else if (!std::strcmp(title, "MemFree:") || !std::strcmp(title, "Buffers:") || !std::strcmp(title, "Cached:"))
                    free += double(kib) * 1024;
            }
            std::fclose(f);
        }
        s_.mem_total = total;
        s_.mem_free = free;
        break;
    }
    case kLoad: { // the share of all CPUs busy, and this process's, since the last sample [%]
        long n = ::sysconf(_SC_NPROCESSORS_ONLN);
        s_.cpus = n > 0 ? double(n) : 1.0;
        double busy = system_busy_s(), cpu = process_cpu_s(), wall = wall_s();
        if (last_sys_busy_s_ >= 0 && wall > last_wall_s_) {
            double span = (wall - last_wall_s_) * s_.cpus;
            s_.sys_load = std::clamp(100.0 * (busy - last_sys_busy_s_) / span, 0.0, 100.0);
            s_.ioc_load = std::clamp(100.0 * (cpu - last_proc_cpu_s_) / span, 0.0, 100.0);
        }
        last_sys_busy_s_ = busy;
        last_proc_cpu_s_ = cpu;
        last_wall_s_ = wall;
        s_.zone_temp = 0;
        if (std::FILE* f = std::fopen("/sys/class/thermal/thermal_zone0/temp", "r")) {
            long mc = 0;
            if (std::fscanf(f, "%ld", &mc) == 1) s_.zone_temp = double(mc);
            std::fclose(f);
        }
        break;
    }
    case kFd: { // the open descriptors (/proc/self/fd) and the soft limit
        double used = 0;
        if (DIR* d = ::opendir("/proc/self/fd")) {
            while (dirent* e = ::readdir(d))
                if (e->d_name[0] != '.') used += 1;
            ::closedir(d);
            used -= 1; // the directory's own descriptor
        }
        s_.fd_used = used;
        rlimit lim{};
        s_.fd_max = ::getrlimit(RLIMIT_NOFILE, &lim) == 0 ? double(lim.rlim_cur) : 0;
        break;
    }
    case kCa: {
        CaCounts c = ca_counts_ ? ca_counts_() : CaCounts{};
        s_.ca_clients = c.clients;
        s_.ca_channels = c.channels;
        break;
    }
    default: break;
    }
    (void)now_s;
}

double IocStats::value(int param) const {
    switch (param) {
    case kParamFreeBytes: return s_.mem_free;
    case kParamAllocBytes: return s_.mem_alloc;
    case kParamTotalBytes: return s_.mem_total;
    case kParamSysLoad: return s_.sys_load;
    case kParamIocLoad:
    case kParamCpuCompat: return s_.ioc_load;
    case kParamCpus: return s_.cpus;
    case kParamFd: return s_.fd_used;
    case kParamMaxFd: return s_.fd_max;
    case kParamCaClients: return s_.ca_clients;
    case kParamCaChannels: return s_.ca_channels;
    case kParamMinDataMbuf:
    case kParamMinSysMbuf: return 100; // no mbuf pools: none is short
    case kParamRecords: return records_;
    case kParamPid: return double(::getpid());
    case kParamPpid: return double(::getppid());
    case kParamZoneTemp: return s_.zone_temp;
    default: return 0;
    }
}

void IocStats::tick(Database& db, double now_s) {
    for (int g = 0; g < kStatic; ++g) {
        if (next_s_[g] != 0 && now_s < next_s_[g]) continue;
        next_s_[g] = now_s + period_s_[g]; // the first tick samples at once: no record waits a period
        sample(Group(g), now_s);
        // scanIoRequest: the group's I/O Intr records (by index: processing may bind more)
        for (std::size_t i = 0; i < devices_.size(); ++i) {
            Record* r = devices_[i]->record();
            if (r && devices_[i]->group() == g && r->scan == 2 /* I/O Intr */) db.process(*r);
        }
    }
}

const char* IocStats::database_text() {
    // The records of devIocStats's iocAdmin/Db/ioc.template and of iocAdminSoft.substitutions's
    // environment records, under the same names, with the same device parameters and alarm limits
    // (so that alarm handler and archiver set-ups made for them work), READACF and SYSRESET with
    // their subroutines (set_admin_hooks).
    return R"DB(
record(sub, "$(IOC):READACF") {
  field(DESC, "$(IOC) ACF Update")
  field(INAM, "asSubInit")
  field(SNAM, "asSubProcess")
  field(BRSV, "INVALID")
}
record(sub, "$(IOC):SYSRESET") {
  alias("$(IOC):SysReset")
  field(DESC, "IOC Restart")
  field(SNAM, "rebootProc")
  field(BRSV, "INVALID")
  field(L, "1")
}
record(mbbo, "$(IOC):ACCESS") {
  field(DESC, "$(IOC) Acc Mode")
  field(PINI, "YES")
  field(ZRST, "Running")     field(ZRSV, "NO_ALARM")
  field(ONST, "Maintenance") field(ONSV, "MINOR")
  field(TWST, "Test")        field(TWSV, "MINOR")
  field(THST, "OFFLINE")     field(THSV, "MAJOR")
  info(autosaveFields, "VAL")
}
record(stringin, "$(IOC):STARTTOD") {
  field(DESC, "Time and date of startup")
  field(DTYP, "Soft Timestamp")
  field(PINI, "YES")
  field(INP, "@%m/%d/%Y %H:%M:%S")
}
record(stringin, "$(IOC):TOD") {
  field(DESC, "Current time and date")
  field(DTYP, "Soft Timestamp")
  field(SCAN, "1 second")
  field(INP, "@%m/%d/%Y %H:%M:%S")
}
record(calcout, "$(IOC):HEARTBEAT") {
  field(DESC, "1 Hz counter since startup")
  field(CALC, "(A<2147483647)?A+1:1")
  field(SCAN, "1 second")
  field(INPA, "$(IOC):HEARTBEAT")
}
record(calcout, "$(IOC):START_CNT") {
  field(DESC, "Increments at startup")
  field(CALC, "A+1")
  field(PINI, "YES")
  field(INPA, "$(IOC):START_CNT")
  info(autosaveFields_pass0, "VAL")
}
record(ai, "$(IOC):CA_CLNT_CNT") {
  field(DESC, "Number of CA Clients")
  field(SCAN, "I/O Intr") field(DTYP, "IOC stats") field(INP, "@ca_clients")
  field(HOPR, "200") field(HIHI, "175") field(HIGH, "100") field(HHSV, "MAJOR") field(HSV, "MINOR")
}
record(ai, "$(IOC):CA_CONN_CNT") {
  field(DESC, "Number of CA Connections")
  field(SCAN, "I/O Intr") field(DTYP, "IOC stats") field(INP, "@ca_connections")
  field(HOPR, "5000") field(HIHI, "4500") field(HIGH, "4000") field(HHSV, "MAJOR") field(HSV, "MINOR")
}
record(ai, "$(IOC):RECORD_CNT") {
  field(DESC, "Number of Records")
  field(PINI, "YES") field(DTYP, "IOC stats") field(INP, "@records")
}
record(ai, "$(IOC):FD_MAX") {
  field(DESC, "Max File Descriptors")
  field(PINI, "YES") field(DTYP, "IOC stats") field(INP, "@maxfd")
}
record(ai, "$(IOC):FD_CNT") {
  field(DESC, "Allocated File Descriptors")
  field(SCAN, "I/O Intr") field(DTYP, "IOC stats") field(INP, "@fd")
  field(FLNK, "$(IOC):FD_FREE  PP MS")
}
record(calc, "$(IOC):FD_FREE") {
  field(DESC, "Available FDs")
  field(CALC, "B>0?B-A:C")
  field(INPA, "$(IOC):FD_CNT  NPP MS") field(INPB, "$(IOC):FD_MAX  NPP MS") field(INPC, "1000")
  field(HOPR, "150") field(LOLO, "5") field(LOW, "20") field(LLSV, "MAJOR") field(LSV, "MINOR")
}
record(ai, "$(IOC):SYS_CPU_LOAD") {
  field(DESC, "System CPU Load")
  field(SCAN, "I/O Intr") field(DTYP, "IOC stats") field(INP, "@sys_cpuload")
  field(EGU, "%") field(PREC, "1")
  field(HOPR, "100") field(HIHI, "80") field(HIGH, "70") field(HHSV, "MAJOR") field(HSV, "MINOR")
}
record(ai, "$(IOC):IOC_CPU_LOAD") {
  alias("$(IOC):LOAD")
  field(DESC, "IOC CPU Load")
  field(SCAN, "I/O Intr") field(DTYP, "IOC stats") field(INP, "@ioc_cpuload")
  field(EGU, "%") field(PREC, "1")
  field(HOPR, "100") field(HIHI, "80") field(HIGH, "70") field(HHSV, "MAJOR") field(HSV, "MINOR")
}
record(ai, "$(IOC):CPU_CNT") {
  field(DESC, "Number of CPUs")
  field(DTYP, "IOC stats") field(INP, "@no_of_cpus") field(PINI, "YES")
}
record(ai, "$(IOC):SUSP_TASK_CNT") {
  field(DESC, "Number Suspended Tasks")
  field(SCAN, "I/O Intr") field(DTYP, "IOC stats") field(INP, "@suspended_tasks")
  field(HIHI, "1") field(HHSV, "MAJOR")
}
record(ai, "$(IOC):MEM_USED") {
  field(DESC, "Allocated Memory")
  field(SCAN, "I/O Intr") field(DTYP, "IOC stats") field(INP, "@allocated_bytes") field(EGU, "byte")
}
record(ai, "$(IOC):MEM_FREE") {
  field(DESC, "Free Memory")
  field(SCAN, "I/O Intr") field(DTYP, "IOC stats") field(INP, "@free_bytes") field(EGU, "byte")
  field(LLSV, "MAJOR") field(LSV, "MINOR")
}
record(ai, "$(IOC):MEM_MAX") {
  field(DESC, "Maximum Memory")
  field(SCAN, "I/O Intr") field(DTYP, "IOC stats") field(INP, "@total_bytes") field(EGU, "byte")
}
record(ao, "$(IOC):CA_UPD_TIME") {
  field(DESC, "CA Check Update Period")
  field(DTYP, "IOC stats") field(OUT, "@ca_scan_rate")
  field(EGU, "sec") field(DRVH, "60") field(DRVL, "1") field(HOPR, "60") field(VAL, "15") field(PINI, "YES")
}
record(ao, "$(IOC):FD_UPD_TIME") {
  field(DESC, "FD Check Update Period")
  field(DTYP, "IOC stats") field(OUT, "@fd_scan_rate")
  field(EGU, "sec") field(DRVH, "60") field(DRVL, "1") field(HOPR, "60") field(VAL, "20") field(PINI, "YES")
}
record(ao, "$(IOC):LOAD_UPD_TIME") {
  field(DESC, "CPU Check Update Period")
  field(DTYP, "IOC stats") field(OUT, "@cpu_scan_rate")
  field(EGU, "sec") field(DRVH, "60") field(DRVL, "1") field(HOPR, "60") field(VAL, "10") field(PINI, "YES")
}
record(ao, "$(IOC):MEM_UPD_TIME") {
  field(DESC, "Memory Check Update Period")
  field(DTYP, "IOC stats") field(OUT, "@memory_scan_rate")
  field(EGU, "sec") field(DRVH, "60") field(DRVL, "1") field(HOPR, "60") field(VAL, "10") field(PINI, "YES")
}
record(stringin, "$(IOC):ST_SCRIPT1") {
  field(DESC, "Startup Script Part1") field(DTYP, "IOC stats") field(INP, "@startup_script_1") field(PINI, "YES")
}
record(stringin, "$(IOC):ST_SCRIPT2") {
  field(DESC, "Startup Script Part2") field(DTYP, "IOC stats") field(INP, "@startup_script_2") field(PINI, "YES")
}
record(waveform, "$(IOC):ST_SCRIPT") {
  field(DESC, "Startup Script") field(DTYP, "IOC stats") field(INP, "@startup_script")
  field(NELM, "120") field(FTVL, "CHAR") field(PINI, "YES")
}
record(stringin, "$(IOC):KERNEL_VERS") {
  field(DESC, "Kernel Version") field(DTYP, "IOC stats") field(INP, "@kernel_ver") field(PINI, "YES")
}
record(stringin, "$(IOC):EPICS_VERS") {
  field(DESC, "EPICS Version") field(DTYP, "IOC stats") field(INP, "@epics_ver") field(PINI, "YES")
}
record(waveform, "$(IOC):EPICS_VERSION") {
  field(DESC, "EPICS Version") field(DTYP, "IOC stats") field(INP, "@epics_ver")
  field(NELM, "120") field(FTVL, "CHAR") field(PINI, "YES")
}
record(stringin, "$(IOC):HOSTNAME") {
  field(DESC, "Host Name") field(DTYP, "IOC stats") field(INP, "@hostname") field(PINI, "YES")
}
record(stringin, "$(IOC):APP_DIR1") {
  field(DESC, "Application Directory Part 1") field(DTYP, "IOC stats") field(INP, "@pwd1") field(PINI, "YES")
}
record(stringin, "$(IOC):APP_DIR2") {
  field(DESC, "Application Directory Part 2") field(DTYP, "IOC stats") field(INP, "@pwd2") field(PINI, "YES")
}
record(waveform, "$(IOC):APP_DIR") {
  field(DESC, "Application Directory") field(DTYP, "IOC stats") field(INP, "@pwd")
  field(NELM, "160") field(FTVL, "CHAR") field(PINI, "YES")
}
record(stringin, "$(IOC):UPTIME") {
  field(DESC, "Elapsed Time since Start") field(SCAN, "1 second")
  field(DTYP, "IOC stats") field(INP, "@up_time") field(PINI, "YES")
}
record(stringin, "$(IOC):ENGINEER") {
  field(DESC, "Engineer") field(DTYP, "IOC stats") field(INP, "@engineer") field(PINI, "YES")
}
record(stringin, "$(IOC):LOCATION") {
  field(DESC, "Location") field(DTYP, "IOC stats") field(INP, "@location") field(PINI, "YES")
}
record(ai, "$(IOC):PROCESS_ID") {
  field(DESC, "Process ID") field(PINI, "YES") field(DTYP, "IOC stats") field(INP, "@proc_id")
}
record(ai, "$(IOC):PARENT_ID") {
  field(DESC, "Parent Process ID") field(PINI, "YES") field(DTYP, "IOC stats") field(INP, "@parent_proc_id")
}
record(ai, "$(IOC):SYS_ZONE_TEMP") {
  field(DESC, "System Thermal Zone0 Temperature")
  field(SCAN, "I/O Intr") field(DTYP, "IOC stats") field(INP, "@sys_zonetemp") field(EGU, "mCelsius")
  field(LOPR, "0") field(HIHI, "90000") field(HIGH, "80000") field(HHSV, "MAJOR") field(HSV, "MINOR")
}
record(stringin, "$(IOC):CA_ADDR_LIST") { field(DESC, "EPICS_CA_ADDR_LIST") field(DTYP, "IOC epics var") field(INP, "@EPICS_CA_ADDR_LIST") field(PINI, "YES") }
record(stringin, "$(IOC):CA_CONN_TIME") { field(DESC, "EPICS_CA_CONN_TMO") field(DTYP, "IOC epics var") field(INP, "@EPICS_CA_CONN_TMO") field(PINI, "YES") }
record(stringin, "$(IOC):CA_AUTO_ADDR") { field(DESC, "EPICS_CA_AUTO_ADDR_LIST") field(DTYP, "IOC epics var") field(INP, "@EPICS_CA_AUTO_ADDR_LIST") field(PINI, "YES") }
record(stringin, "$(IOC):CA_RPTR_PORT") { field(DESC, "EPICS_CA_REPEATER_PORT") field(DTYP, "IOC epics var") field(INP, "@EPICS_CA_REPEATER_PORT") field(PINI, "YES") }
record(stringin, "$(IOC):CA_SRVR_PORT") { field(DESC, "EPICS_CA_SERVER_PORT") field(DTYP, "IOC epics var") field(INP, "@EPICS_CA_SERVER_PORT") field(PINI, "YES") }
record(stringin, "$(IOC):CA_MAX_ARRAY") { field(DESC, "EPICS_CA_MAX_ARRAY_BYTES") field(DTYP, "IOC epics var") field(INP, "@EPICS_CA_MAX_ARRAY_BYTES") field(PINI, "YES") }
record(stringin, "$(IOC):CA_SRCH_TIME") { field(DESC, "EPICS_CA_MAX_SEARCH_PERIOD") field(DTYP, "IOC epics var") field(INP, "@EPICS_CA_MAX_SEARCH_PERIOD") field(PINI, "YES") }
record(stringin, "$(IOC):CA_BEAC_TIME") { field(DESC, "EPICS_CA_BEACON_PERIOD") field(DTYP, "IOC epics var") field(INP, "@EPICS_CA_BEACON_PERIOD") field(PINI, "YES") }
record(stringin, "$(IOC):TIMEZONE") { field(DESC, "EPICS_TZ") field(DTYP, "IOC epics var") field(INP, "@EPICS_TZ") field(PINI, "YES") }
record(stringin, "$(IOC):TS_NTP_INET") { field(DESC, "EPICS_TS_NTP_INET") field(DTYP, "IOC epics var") field(INP, "@EPICS_TS_NTP_INET") field(PINI, "YES") }
record(stringin, "$(IOC):IOC_LOG_PORT") { field(DESC, "EPICS_IOC_LOG_PORT") field(DTYP, "IOC epics var") field(INP, "@EPICS_IOC_LOG_PORT") field(PINI, "YES") }
record(stringin, "$(IOC):IOC_LOG_INET") { field(DESC, "EPICS_IOC_LOG_INET") field(DTYP, "IOC epics var") field(INP, "@EPICS_IOC_LOG_INET") field(PINI, "YES") }
)DB";
}

} // namespace beamctl::pv
