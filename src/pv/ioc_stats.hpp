// IOC health as devIocStats serves it: the device supports "IOC stats" (ai, ao, stringin,
// waveform), "IOC env var" and "IOC epics var" (stringin) with devIocStats's INST_IO parameters,
// so that the iocAdmin databases facilities load (ioc.template, iocAdminSoft.substitutions) read
// this process; and the built-in record set (`database_text`) an IOC serves as $(IOC):HEARTBEAT,
// $(IOC):UPTIME, $(IOC):IOC_CPU_LOAD, ...
// Values are sampled by group (memory, CPU load, file descriptors, CA), each at its own period
// (the ao "@memory_scan_rate" ... records, devIocStats's defaults otherwise); a sample processes the
// group's SCAN "I/O Intr" records. Threading: the database thread only (Database::scan_periodic).
#pragma once

#include <functional>

#include "pv/link.hpp"

#include <array>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace beamctl::pv {

class Database;
class Record;

class IocStats {
public:
    // The groups devIocStats samples together; kStatic is read once (PINI records).
    enum Group : uint8_t { kMemory, kLoad, kFd, kCa, kStatic, kGroupCount };
    struct CaCounts {
        unsigned clients = 0;  // TCP circuits
        unsigned channels = 0; // channels over all circuits
    };

    IocStats();
    ~IocStats();
    IocStats(const IocStats&) = delete;
    IocStats& operator=(const IocStats&) = delete;

    // The device of record r's INST_IO link l for DTYP `dtyp` (one of the IOC stats choices of
    // kMenuSoftDtyp); nullptr with *why for a parameter devIocStats does not have.
    LinkDevice* bind(Record& r, const Link& l, uint16_t dtyp, std::string* why);
    // Where CA_CLNT_CNT and CA_CONN_CNT come from (the CA server's owner sets it).
    void set_ca_counts(std::function<CaCounts()> f) { ca_counts_ = std::move(f); }
    // RECORD_CNT: the number of records (the database sets it at init).
    void set_record_count(std::size_t n) { records_ = double(n); }
    // Samples every group whose period has passed and processes its I/O Intr records [s].
    void tick(Database& db, double now_s);
    // The sampling period of a group [s] (the ao "@..._scan_rate" records write it).
    double period(Group g) const { return period_s_[g]; }

    // What EPICS_VERS and EPICS_VERSION read ("beamctl 0.1.0, EPICS 7.0.8 records"); the
    // program sets it once at start.
    static void set_release(std::string text);
    // What devIocStats's two subroutine records do, as the program that serves them can: READACF
    // (a put of 1; asSubProcess) calls `reload_acf` (true: reloaded) and reads 0 again, a failure
    // raising its BRSV alarm; SYSRESET (rebootProc, with A..F 0 and L 1) calls `restart` — for
    // beamctl a clean stop, which procServ or systemd follow with a new start. Either may be
    // empty (that record then fails its processing). Set by the program once, on its loop thread.
    static void set_admin_hooks(std::function<bool()> reload_acf, std::function<void()> restart);
    // The records of devIocStats's ioc.template and iocAdminSoft's environment records, for the
    // macro IOC (the IOC's name), as .db text: what `beamctl run` serves for `ioc.stats` and
    // `beamctl softioc --ioc-stats NAME` loads.
    static const char* database_text();

private:
    class Device;
    struct Sample {
        double mem_alloc = 0, mem_free = 0, mem_total = 0; // [byte]
        double sys_load = 0, ioc_load = 0, cpus = 1;       // [%], [%], count
        double fd_used = 0, fd_max = 0;
        double ca_clients = 0, ca_channels = 0;
        double zone_temp = 0; // [m°C] thermal zone 0
    };
    void sample(Group g, double now_s);
    double value(int param) const;

    std::array<double, kGroupCount> period_s_; // [s]
    std::array<double, kGroupCount> next_s_{}; // [s] 0: not started
    Sample s_;
    double records_ = 0;
    // the CPU-time readings of the last load sample: system busy ticks, this process's CPU [s], wall [s]
    double last_sys_busy_s_ = -1, last_proc_cpu_s_ = 0, last_wall_s_ = 0;
    std::function<CaCounts()> ca_counts_;
    std::vector<std::unique_ptr<Device>> devices_;
};

} // namespace beamctl::pv
