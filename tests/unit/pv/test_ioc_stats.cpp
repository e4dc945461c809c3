// devIocStats's device supports and record set (issue 41, item 8): the records of its ioc.template
// load and read this process (CPU count, PID, file descriptors, memory), sample each group at the
// period its ao record sets, count CA clients through the owner's hook, and refuse what
// devIocStats has not. Time is virtual: scan_periodic.
#include "db_fixture.hpp"
#include "pv/ioc_stats.hpp"

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdlib>
#include <regex>
#include <string>

using namespace beamctl;
using namespace beamctl::pv;

namespace {

struct IocStatsTest : DbTest {
    double now = 1000;
    void load_builtin() {
        db.load(parse_db(IocStats::database_text(), "iocstats.db", {{"IOC", "TEST"}}));
        db.init_records();
    }
    void advance(double seconds) {
        for (double end = now + seconds; now < end - 1e-9;) db.scan_periodic(now += 0.01);
    }
    std::string chars(const char* name) {
        char buf[200] = {};
        uint32_t n = db.get(addr(name), Prim::Char, buf, sizeof buf - 1);
        return std::string(buf, strnlen(buf, n));
    }
};

} // namespace

TEST_F(IocStatsTest, BuiltinSetReadsThisProcess) {
    load_builtin();
    advance(0.05); // the first sample of every group processes its I/O Intr records
    EXPECT_DOUBLE_EQ(getd("TEST:CPU_CNT"), double(::sysconf(_SC_NPROCESSORS_ONLN)));
    EXPECT_DOUBLE_EQ(getd("TEST:PROCESS_ID"), double(::getpid()));
    EXPECT_DOUBLE_EQ(getd("TEST:PARENT_ID"), double(::getppid()));
    EXPECT_GT(getd("TEST:FD_CNT"), 2);        // stdin, stdout, stderr at least
    EXPECT_GT(getd("TEST:FD_MAX"), getd("TEST:FD_CNT"));
    EXPECT_DOUBLE_EQ(getd("TEST:FD_FREE"), getd("TEST:FD_MAX") - getd("TEST:FD_CNT")); // the calc after it
    EXPECT_GT(getd("TEST:MEM_USED"), 1e6);    // this test's resident set
    EXPECT_GT(getd("TEST:MEM_MAX"), getd("TEST:MEM_FREE"));
    EXPECT_GE(getd("TEST:IOC_CPU_LOAD"), 0);
    EXPECT_LE(getd("TEST:IOC_CPU_LOAD"), 100);
    EXPECT_DOUBLE_EQ(getd("TEST:LOAD"), getd("TEST:IOC_CPU_LOAD")); // alias
    EXPECT_DOUBLE_EQ(getd("TEST:RECORD_CNT"), double(db.size()));
    EXPECT_EQ(gets("TEST:CA_CLNT_CNT.SEVR"), "NO_ALARM") << gets("TEST:CA_CLNT_CNT.STAT") << " " << gets("TEST:CA_CLNT_CNT.AMSG");
    EXPECT_EQ(gets("TEST:EPICS_VERS"), chars("TEST:EPICS_VERSION"));
    EXPECT_NE(gets("TEST:EPICS_VERS").find("EPICS 7.0.8"), std::string::npos) << gets("TEST:EPICS_VERS");
    EXPECT_EQ(gets("TEST:KERNEL_VERS").rfind("Linux ", 0), 0u) << gets("TEST:KERNEL_VERS");
    char cwd[4096];
    ASSERT_TRUE(::getcwd(cwd, sizeof cwd));
    EXPECT_EQ(chars("TEST:APP_DIR"), std::string(cwd).substr(0, 159));
    EXPECT_EQ(gets("TEST:APP_DIR1"), std::string(cwd).substr(0, 39));
    EXPECT_EQ(gets("TEST:CA_SRVR_PORT").empty(), false);
    EXPECT_EQ(gets("TEST:ACCESS"), "Running");
    EXPECT_DOUBLE_EQ(getd("TEST:START_CNT"), 1);
    EXPECT_TRUE(db.record_errors().empty());
}

TEST_F(IocStatsTest, HeartbeatAndUptimeCountSeconds) {
    load_builtin();
    advance(0.05);
    double beat = getd("TEST:HEARTBEAT");
    EXPECT_TRUE(std::regex_match(gets("TEST:UPTIME"), std::regex("([0-9]+ days?, )?[0-9]{2}:[0-9]{2}:[0-9]{2}")))
        << gets("TEST:UPTIME");
    advance(3.0);
    EXPECT_DOUBLE_EQ(getd("TEST:HEARTBEAT"), beat + 3);
}

TEST_F(IocStatsTest, CaCountsComeFromTheServerHookAtTheCaPeriod) {
    unsigned clients = 2, channels = 7;
    db.ioc_stats().set_ca_counts([&] { return IocStats::CaCounts{clients, channels}; });
    load_builtin();
    advance(0.05);
    EXPECT_DOUBLE_EQ(getd("TEST:CA_CLNT_CNT"), 2);
    EXPECT_DOUBLE_EQ(getd("TEST:CA_CONN_CNT"), 7);
    clients = 180; // past HIHI 175: MAJOR
    advance(14.0);
    EXPECT_DOUBLE_EQ(getd("TEST:CA_CLNT_CNT"), 2) << "sampled every CA_UPD_TIME = 15 s";
    advance(1.1);
    EXPECT_DOUBLE_EQ(getd("TEST:CA_CLNT_CNT"), 180);
    EXPECT_EQ(gets("TEST:CA_CLNT_CNT.SEVR"), "MAJOR");
    put("TEST:CA_UPD_TIME", 2); // a shorter period takes effect at once
    EXPECT_DOUBLE_EQ(db.ioc_stats().period(IocStats::kCa), 2);
    clients = 3;
    advance(0.05);
    EXPECT_DOUBLE_EQ(getd("TEST:CA_CLNT_CNT"), 3);
    put("TEST:CA_UPD_TIME", 0); // DRVL 1 holds it at 1 s
    EXPECT_DOUBLE_EQ(db.ioc_stats().period(IocStats::kCa), 1);
}

TEST_F(IocStatsTest, EnvironmentRecordsReadVariablesAndBaseDefaults) {
    ::setenv("BEAMCTL_TEST_LOCATION", "hutch 3", 1);
    ::unsetenv("EPICS_CA_CONN_TMO");
    load(R"(
record(stringin, "env") { field(DTYP, "IOC env var") field(INP, "@BEAMCTL_TEST_LOCATION") field(PINI, "YES") }
record(stringin, "none") { field(DTYP, "IOC env var") field(INP, "@BEAMCTL_NO_SUCH_VARIABLE") field(PINI, "YES") }
record(stringin, "tmo") { field(DTYP, "IOC epics var") field(INP, "@EPICS_CA_CONN_TMO") field(PINI, "YES") }
record(stringin, "old") { field(DTYP, "IOC epics var") field(INP, "@EPICS_TIMEZONE") field(PINI, "YES") }
)");
    EXPECT_EQ(gets("env"), "hutch 3");
    EXPECT_EQ(gets("none"), "<not available>");
    EXPECT_EQ(gets("tmo"), "30.0"); // base's default
    // EPICS_TIMEZONE is not one of base 7's parameters (EPICS_TZ is): devIocStats reads it so
    EXPECT_EQ(gets("old"), "<undefined>");
    EXPECT_EQ(gets("old.STAT"), "UDF");
    ASSERT_EQ(db.record_errors().size(), 1u);
    EXPECT_NE(db.record_errors()[0].find("EPICS_TIMEZONE"), std::string::npos) << db.record_errors()[0];
}

TEST_F(IocStatsTest, UnknownParameterFailsOnlyItsRecordAndWrongTypesAreRefused) {
    load(R"(
record(ai, "bad") { field(DTYP, "IOC stats") field(INP, "@cpu_temperature") field(PINI, "YES") }
record(ai, "good") { field(DTYP, "IOC stats") field(INP, "@no_of_cpus") field(PINI, "YES") }
)");
    EXPECT_EQ(gets("bad.SEVR"), "INVALID");
    EXPECT_DOUBLE_EQ(getd("good"), double(::sysconf(_SC_NPROCESSORS_ONLN)));
    ASSERT_EQ(db.record_errors().size(), 1u);
    EXPECT_NE(db.record_errors()[0].find("cpu_temperature"), std::string::npos) << db.record_errors()[0];
    std::string e = load_error(R"(record(longin, "x") { field(DTYP, "IOC stats") field(INP, "@fd") })");
    EXPECT_NE(e.find("has no \"IOC stats\" device support"), std::string::npos) << e;
    e = load_error(R"(record(ai, "x") { field(DTYP, "IOC stats clusts") field(INP, "@clust_info 0 0 0") })");
    EXPECT_NE(e.find("IOC stats clusts"), std::string::npos) << e;
}

TEST_F(IocStatsTest, ReadAcfRereadsTheAccessSecurityFileAndSysResetRestarts) {
    int reloads = 0, restarts = 0;
    bool reload_ok = true;
    IocStats::set_admin_hooks([&] { return ++reloads, reload_ok; }, [&] { ++restarts; });
    load_builtin();
    EXPECT_TRUE(db.record_errors().empty()) << db.record_errors().front(); // the routines are built in
    EXPECT_EQ(put("TEST:READACF", 1), PutStatus::Ok); // asSubProcess: a put of 1
    EXPECT_EQ(reloads, 1);
    EXPECT_DOUBLE_EQ(getd("TEST:READACF"), 0);        // reads 0 again
    EXPECT_EQ(gets("TEST:READACF.SEVR"), "NO_ALARM");
    EXPECT_EQ(put("TEST:READACF", 0), PutStatus::Ok); // 0 does nothing
    EXPECT_EQ(reloads, 1);
    reload_ok = false;
    put("TEST:READACF", 1);
    EXPECT_EQ(reloads, 2);
    EXPECT_EQ(gets("TEST:READACF.SEVR"), "INVALID"); // BRSV
    EXPECT_EQ(put("TEST:SYSRESET.A", 1), PutStatus::Ok);
    put("TEST:SYSRESET.PROC", 1);
    EXPECT_EQ(restarts, 0);                          // rebootProc: only with A..F 0 and L 1
    put("TEST:SYSRESET.A", 0);                       // A is pp(TRUE): this processes it
    EXPECT_EQ(restarts, 1);
    put("TEST:SysReset.PROC", 1);                    // the alias
    EXPECT_EQ(restarts, 2);
    IocStats::set_admin_hooks({}, {});
    put("TEST:SYSRESET.PROC", 1);
    EXPECT_EQ(restarts, 2);
    EXPECT_EQ(gets("TEST:SYSRESET.SEVR"), "INVALID"); // no way to restart here
}
