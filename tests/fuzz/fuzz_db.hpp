// A small database with one record of each type, shared by the CA fuzz targets.
#pragma once

#include "pv/database.hpp"

inline beamctl::pv::Database& fuzz_database() {
    static beamctl::pv::Database* db = [] {
        auto* d = new beamctl::pv::Database;
        const char* text = R"(
record(ai, "f:ai") { field(HIHI, "10") field(HHSV, "MAJOR") field(PREC, "3") field(EGU, "mm") }
record(ao, "f:ao") { field(DRVH, "5") field(DRVL, "-5") }
record(bi, "f:bi") { field(ZNAM, "Off") field(ONAM, "On") }
record(bo, "f:bo") { field(ZNAM, "Off") field(ONAM, "On") }
record(longin, "f:li") {}
record(longout, "f:lo") { field(DRVH, "100") }
record(mbbi, "f:mbbi") { field(ZRST, "A") field(ONST, "B") }
record(mbbo, "f:mbbo") { field(ZRST, "A") field(ONST, "B") field(ZRVL, "3") }
record(stringin, "f:si") {}
record(stringout, "f:so") {}
record(waveform, "f:wf") { field(FTVL, "DOUBLE") field(NELM, "64") }
record(waveform, "f:ws") { field(FTVL, "STRING") field(NELM, "4") }
record(waveform, "f:wc") { field(FTVL, "CHAR") field(NELM, "128") }
)";
        d->load(beamctl::pv::parse_db(text, "fuzz.db", {}));
        d->init_records();
        return d;
    }();
    return *db;
}
