// The fly scan's HDF5/NeXus writer (daq::NexusFile): rows written in several appends read back
// with HDF5's C API (values, shapes, chunks, types), the NeXus attributes, a SWMR reader in
// another process following the file as it grows, errors that name the path and print nothing,
// bad columns refused before the file exists, and no allocation per append after the first.
#include "../alloc_counter.hpp"
#include "../temp_dir.hpp"
#include "core/error.hpp"
#include "daq/nexus_file.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <cstring>
#include <filesystem>
#include <poll.h>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

using beamctl::Error;
using beamctl::daq::NexusColumn;
using beamctl::daq::NexusFile;
using beamctl::daq::NexusOptions;
using beamctl::test::TempDir;

namespace {

// An HDF5 id for the test's reads, closed at the end of its scope.
struct Id {
    hid_t id;
    herr_t (*close)(hid_t);
    ~Id() {
        if (id >= 0) close(id);
    }
};

std::vector<NexusColumn> three_columns() {
    return {{"ax1_enc_actpos", "mm", "ax1.enc.actpos", "Value"},
            {"i0", "", "ec0.s3.ai1", "Sum"},
            {"ax1_velocity", "mm/s", "ax1.traj.velocity", "Diff"}};
}

// Row r of the test data: cycle 1000 + r, 1 ms apart from 5 s, column j is r + j / 10.
constexpr uint64_t kCycle0 = 1000, kT0 = 5'000'000'000, kDt = 1'000'000;
double value(uint64_t r, std::size_t j) {
    return double(r) + double(j) / 10;
}

// Appends rows [first, first + n) of the test data.
void append_rows(NexusFile& f, uint64_t first, std::size_t n) {
    std::vector<uint64_t> cycle(n), t(n);
    std::vector<double> v(n * f.columns());
    for (std::size_t i = 0; i < n; ++i) {
        cycle[i] = kCycle0 + first + i;
        t[i] = kT0 + (first + i) * kDt;
        for (std::size_t j = 0; j < f.columns(); ++j) v[i * f.columns() + j] = value(first + i, j);
    }
    f.append(cycle.data(), t.data(), v.data(), n);
}

// A string attribute of the object at `obj`; "<none>" if it has none, "<not a string>" if not one.
std::string attr(hid_t file, const char* obj, const char* name) {
    if (H5Aexists_by_name(file, obj, name, H5P_DEFAULT) <= 0) return "<none>";
    Id a{H5Aopen_by_name(file, obj, name, H5P_DEFAULT, H5P_DEFAULT), H5Aclose};
    Id type{H5Aget_type(a.id), H5Tclose};
    if (H5Tget_class(type.id) != H5T_STRING || H5Tis_variable_str(type.id) <= 0)
        return "<not a string>";
    Id mem{H5Tcopy(H5T_C_S1), H5Tclose};
    H5Tset_size(mem.id, H5T_VARIABLE);
    H5Tset_cset(mem.id, H5T_CSET_UTF8);
    char* p = nullptr;
    if (H5Aread(a.id, mem.id, &p) < 0) return "<unreadable>";
    std::string s = p ? p : "";
    H5free_memory(p);
    return s;
}

struct Shape {
    hsize_t rows = 0, max_rows = 0, chunk_rows = 0;
};
Shape shape(hid_t ds) {
    Shape s;
    Id space{H5Dget_space(ds), H5Sclose};
    EXPECT_EQ(H5Sget_simple_extent_ndims(space.id), 1);
    H5Sget_simple_extent_dims(space.id, &s.rows, &s.max_rows);
    Id dcpl{H5Dget_create_plist(ds), H5Pclose};
    EXPECT_EQ(H5Pget_layout(dcpl.id), H5D_CHUNKED);
    H5Pget_chunk(dcpl.id, 1, &s.chunk_rows);
    return s;
}

template <typename T> std::vector<T> read_all(hid_t ds, hid_t mem_type) {
    std::vector<T> v(shape(ds).rows);
    if (!v.empty()) {
        EXPECT_GE(H5Dread(ds, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()), 0);
    }
    return v;
}

bool file_type_is(hid_t ds, hid_t type) {
    Id t{H5Dget_type(ds), H5Tclose};
    return H5Tequal(t.id, type) > 0;
}

} // namespace

TEST(NexusFile, RowsOfSeveralAppendsReadBack) {
    TempDir dir;
    const std::string path = dir.file("scan.h5");
    NexusOptions opt;
    opt.chunk_rows = 5; // appends of 7, 1 and 13 rows start and end inside chunks
    NexusFile f(path, three_columns(), opt);
    EXPECT_EQ(f.path(), path);
    EXPECT_EQ(f.columns(), 3u);
    append_rows(f, 0, 7);
    append_rows(f, 7, 1);
    append_rows(f, 8, 13);
    EXPECT_EQ(f.rows(), 21u);
    EXPECT_EQ(f.bytes(), 21u * 8 * (3 + 3));
    f.close();
    EXPECT_FALSE(f.is_open());
    EXPECT_EQ(f.rows(), 21u);

    Id file{H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose};
    ASSERT_GE(file.id, 0);
    for (const char* name :
         {"ax1_enc_actpos", "i0", "ax1_velocity", "cycle", "time", "timestamp_ns"}) {
        SCOPED_TRACE(name);
        Id ds{H5Dopen2(file.id, (std::string("/entry/data/") + name).c_str(), H5P_DEFAULT),
              H5Dclose};
        ASSERT_GE(ds.id, 0);
        Shape s = shape(ds.id);
        EXPECT_EQ(s.rows, 21u);
        EXPECT_EQ(s.max_rows, H5S_UNLIMITED);
        EXPECT_EQ(s.chunk_rows, 5u);
    }
    const char* columns[] = {"/entry/data/ax1_enc_actpos", "/entry/data/i0",
                             "/entry/data/ax1_velocity"};
    for (std::size_t j = 0; j < 3; ++j) {
        Id ds{H5Dopen2(file.id, columns[j], H5P_DEFAULT), H5Dclose};
        EXPECT_TRUE(file_type_is(ds.id, H5T_IEEE_F64LE));
        std::vector<double> v = read_all<double>(ds.id, H5T_NATIVE_DOUBLE);
        ASSERT_EQ(v.size(), 21u);
        for (uint64_t r = 0; r < 21; ++r)
            EXPECT_EQ(v[r], value(r, j)) << columns[j] << " row " << r;
    }
    Id cycle_ds{H5Dopen2(file.id, "/entry/data/cycle", H5P_DEFAULT), H5Dclose};
    Id ts_ds{H5Dopen2(file.id, "/entry/data/timestamp_ns", H5P_DEFAULT), H5Dclose};
    Id time_ds{H5Dopen2(file.id, "/entry/data/time", H5P_DEFAULT), H5Dclose};
    EXPECT_TRUE(file_type_is(cycle_ds.id, H5T_STD_U64LE));
    EXPECT_TRUE(file_type_is(ts_ds.id, H5T_STD_U64LE));
    EXPECT_TRUE(file_type_is(time_ds.id, H5T_IEEE_F64LE));
    std::vector<uint64_t> cycle = read_all<uint64_t>(cycle_ds.id, H5T_NATIVE_UINT64);
    std::vector<uint64_t> ts = read_all<uint64_t>(ts_ds.id, H5T_NATIVE_UINT64);
    std::vector<double> time = read_all<double>(time_ds.id, H5T_NATIVE_DOUBLE);
    ASSERT_EQ(cycle.size(), 21u);
    ASSERT_EQ(ts.size(), 21u);
    ASSERT_EQ(time.size(), 21u);
    for (uint64_t r = 0; r < 21; ++r) {
        EXPECT_EQ(cycle[r], kCycle0 + r);
        EXPECT_EQ(ts[r], kT0 + r * kDt);
        EXPECT_DOUBLE_EQ(time[r], double(r) * 1e-3); // [s] since the first row
    }
}

TEST(NexusFile, NexusGroupsAndAttributes) {
    TempDir dir;
    const std::string path = dir.file("scan.h5");
    NexusOptions opt;
    opt.title = "fly scan of ax1";
    opt.attributes = {{"ioc", "BL01:DAQ"}, {"start_time", "2024-05-02T10:11:12Z"}};
    {
        NexusFile f(path, three_columns(), opt);
        append_rows(f, 0, 3);
    } // the destructor closes

    Id file{H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose};
    ASSERT_GE(file.id, 0);
    EXPECT_EQ(attr(file.id, "/", "default"), "entry");
    EXPECT_EQ(attr(file.id, "/entry", "NX_class"), "NXentry");
    EXPECT_EQ(attr(file.id, "/entry", "default"), "data");
    EXPECT_EQ(attr(file.id, "/entry", "ioc"), "BL01:DAQ");
    EXPECT_EQ(attr(file.id, "/entry", "start_time"), "2024-05-02T10:11:12Z");
    EXPECT_EQ(attr(file.id, "/entry/data", "NX_class"), "NXdata");
    EXPECT_EQ(attr(file.id, "/entry/data", "axes"), "ax1_enc_actpos"); // the first column
    EXPECT_EQ(attr(file.id, "/entry/data", "signal"), "i0");           // the second
    {
        Id a{H5Aopen_by_name(file.id, "/entry/data", "ax1_enc_actpos_indices", H5P_DEFAULT,
                             H5P_DEFAULT),
             H5Aclose};
        ASSERT_GE(a.id, 0);
        int32_t index = -1;
        EXPECT_GE(H5Aread(a.id, H5T_NATIVE_INT32, &index), 0);
        EXPECT_EQ(index, 0);
    }
    EXPECT_EQ(attr(file.id, "/entry/data/ax1_enc_actpos", "units"), "mm");
    EXPECT_EQ(attr(file.id, "/entry/data/ax1_enc_actpos", "source"), "ax1.enc.actpos");
    EXPECT_EQ(attr(file.id, "/entry/data/ax1_enc_actpos", "capture_mode"), "Value");
    EXPECT_EQ(attr(file.id, "/entry/data/i0", "units"), "<none>"); // empty units: no attribute
    EXPECT_EQ(attr(file.id, "/entry/data/i0", "source"), "ec0.s3.ai1");
    EXPECT_EQ(attr(file.id, "/entry/data/i0", "capture_mode"), "Sum");
    EXPECT_EQ(attr(file.id, "/entry/data/ax1_velocity", "units"), "mm/s");
    EXPECT_EQ(attr(file.id, "/entry/data/ax1_velocity", "capture_mode"), "Diff");
    EXPECT_EQ(attr(file.id, "/entry/data/time", "units"), "s");
    EXPECT_EQ(attr(file.id, "/entry/data/timestamp_ns", "units"), "ns");

    Id title{H5Dopen2(file.id, "/entry/title", H5P_DEFAULT), H5Dclose};
    ASSERT_GE(title.id, 0);
    Id mem{H5Tcopy(H5T_C_S1), H5Tclose};
    H5Tset_size(mem.id, H5T_VARIABLE);
    char* p = nullptr;
    ASSERT_GE(H5Dread(title.id, mem.id, H5S_ALL, H5S_ALL, H5P_DEFAULT, &p), 0);
    EXPECT_STREQ(p, "fly scan of ax1");
    H5free_memory(p);
}

TEST(NexusFile, AxisAndSignalDefaultsAndChoices) {
    TempDir dir;
    { NexusFile f(dir.file("one.h5"), {{"i0", "", "ec0.s3.ai1", "Sum"}}); }
    NexusOptions opt;
    opt.axis = "time";
    opt.signal = "ax1_velocity";
    { NexusFile f(dir.file("chosen.h5"), three_columns(), opt); }

    Id one{H5Fopen(dir.file("one.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose};
    EXPECT_EQ(attr(one.id, "/entry/data", "axes"), "i0"); // one column: axis and signal
    EXPECT_EQ(attr(one.id, "/entry/data", "signal"), "i0");
    EXPECT_EQ(attr(one.id, "/entry", "title"), "<none>");
    EXPECT_LE(H5Lexists(one.id, "/entry/title", H5P_DEFAULT), 0); // no title: no dataset
    Id chosen{H5Fopen(dir.file("chosen.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose};
    EXPECT_EQ(attr(chosen.id, "/entry/data", "axes"), "time");
    EXPECT_EQ(attr(chosen.id, "/entry/data", "signal"), "ax1_velocity");
    EXPECT_GT(H5Aexists_by_name(chosen.id, "/entry/data", "time_indices", H5P_DEFAULT), 0);
}

// The reader is another process: HDF5 shares one open file between all opens of it in a process,
// so a reader in the writer's process would see the writer's memory, not the file.
TEST(NexusFile, SwmrReaderInAnotherProcessSeesFlushedRows) {
    TempDir dir;
    const std::string path = dir.file("swmr.h5");
    int ask[2], answer[2];
    ASSERT_EQ(pipe(ask), 0);
    ASSERT_EQ(pipe(answer), 0);
    // Forked before the writer opens anything (a child must not inherit an open HDF5 file).
    pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
        // Child: at each 'r', (open,) refresh and check every row; reply "rows <n>" [+ faults].
        ::close(ask[1]);
        ::close(answer[0]);
        H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
        hid_t file = -1, col = -1, cyc = -1;
        char cmd = 0;
        while (read(ask[0], &cmd, 1) == 1 && cmd == 'r') {
            if (file < 0) {
                file = H5Fopen(path.c_str(), H5F_ACC_RDONLY | H5F_ACC_SWMR_READ, H5P_DEFAULT);
                col = H5Dopen2(file, "/entry/data/i0", H5P_DEFAULT);
                cyc = H5Dopen2(file, "/entry/data/cycle", H5P_DEFAULT);
            }
            std::string reply;
            hsize_t rows = 0;
            if (file < 0 || col < 0 || cyc < 0) {
                reply = "cannot open for SWMR read";
            } else if (H5Drefresh(col) < 0 || H5Drefresh(cyc) < 0) {
                reply = "H5Drefresh failed";
            } else {
                hid_t space = H5Dget_space(col);
                H5Sget_simple_extent_dims(space, &rows, nullptr);
                H5Sclose(space);
                std::vector<double> v(rows);
                std::vector<uint64_t> c(rows);
                bool read_ok = true;
                if (rows > 0) {
                    read_ok = H5Dread(col, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT,
                                      v.data()) >= 0;
                    read_ok = H5Dread(cyc, H5T_NATIVE_UINT64, H5S_ALL, H5S_ALL, H5P_DEFAULT,
                                      c.data()) >= 0 &&
                              read_ok;
                }
                std::size_t bad = 0;
                for (uint64_t r = 0; r < rows; ++r)
                    bad += v[r] != value(r, 1) || c[r] != kCycle0 + r;
                reply = "rows " + std::to_string(rows) + (read_ok ? "" : " unreadable") +
                        (bad ? " wrong " + std::to_string(bad) : "");
            }
            reply.resize(64, '\0');
            if (write(answer[1], reply.data(), reply.size()) != 64) break;
        }
        if (cyc >= 0) H5Dclose(cyc);
        if (col >= 0) H5Dclose(col);
        if (file >= 0) H5Fclose(file);
        _exit(0);
    }
    ::close(ask[0]);
    ::close(answer[1]);
    // What the reader sees now, within 10 s.
    auto reader_sees = [&]() -> std::string {
        if (write(ask[1], "r", 1) != 1) return "reader gone";
        pollfd p{answer[0], POLLIN, 0};
        if (poll(&p, 1, 10'000) != 1) return "no reply in 10 s";
        char buf[64];
        std::size_t got = 0;
        while (got < sizeof buf) {
            ssize_t k = read(answer[0], buf + got, sizeof buf - got);
            if (k <= 0) return "reader gone";
            got += std::size_t(k);
        }
        return std::string(buf, strnlen(buf, sizeof buf));
    };

    {
        NexusOptions opt;
        opt.chunk_rows = 16;
        NexusFile f(path, three_columns(), opt);
        EXPECT_EQ(reader_sees(), "rows 0"); // opened while the writer is open and empty
        append_rows(f, 0, 10);
        f.flush();
        EXPECT_EQ(reader_sees(), "rows 10");
        append_rows(f, 10, 30);
        append_rows(f, 40, 5);
        f.flush();
        EXPECT_EQ(reader_sees(), "rows 45");
        f.close();
        EXPECT_EQ(reader_sees(), "rows 45");
    }
    ::close(ask[1]); // the reader closes and exits
    ::close(answer[0]);
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
}

TEST(NexusFile, UnwritablePathThrowsNamingItAndPrintsNothing) {
    TempDir dir;
    const std::string path = dir.file("no_such_dir/scan.h5");
    testing::internal::CaptureStderr();
    try {
        NexusFile f(path, three_columns());
        ADD_FAILURE() << "no Error";
    } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_EQ(what.rfind(path + ": cannot create the file: ", 0), 0u) << what;
        EXPECT_NE(what.find("No such file or directory"), std::string::npos) << what;
    }
    EXPECT_EQ(testing::internal::GetCapturedStderr(), ""); // HDF5's own printing is off
}

TEST(NexusFile, BadColumnsAndOptionsAreRefusedBeforeTheFileExists) {
    TempDir dir;
    const std::string path = dir.file("scan.h5");
    auto error = [&](std::vector<NexusColumn> columns, NexusOptions opt = {}) -> std::string {
        try {
            NexusFile f(path, std::move(columns), std::move(opt));
        } catch (const Error& e) {
            return e.what();
        }
        return "no Error";
    };
    EXPECT_EQ(error({{"ax1/enc", "mm", "ax1.enc.actpos", "Value"}}),
              path + ": column 0 name \"ax1/enc\" should not contain '/'");
    EXPECT_EQ(error({{"a", "", "", "Value"}, {"", "", "", "Value"}}),
              path + ": column 1 name \"\" is not a dataset name");
    EXPECT_EQ(error({{"a", "", "", "Value"}, {"a", "", "", "Value"}}),
              path + ": column 1 name \"a\" appears twice");
    EXPECT_EQ(error({{"time", "s", "", "Value"}}),
              path + ": column 0 name \"time\" is reserved (cycle, time and timestamp_ns are "
                     "always written)");
    EXPECT_EQ(error({}), path + ": no columns (at least one is needed)");
    NexusColumn empty{"ai", "", "", "Value"};
    empty.width = 0;
    EXPECT_EQ(error({empty}), path + ": column 0 name \"ai\" has width 0 (at least one value a row)");
    NexusOptions opt;
    opt.axis = "ax2";
    EXPECT_EQ(error(three_columns(), opt), path + ": axis \"ax2\" is not a dataset of /entry/data");
    opt = {};
    opt.attributes = {{"ioc", "a"}, {"ioc", "b"}};
    EXPECT_EQ(error(three_columns(), opt),
              path + ": /entry attribute \"ioc\" is given twice or reserved");
    opt.attributes = {{"NX_class", "NXsubentry"}};
    EXPECT_EQ(error(three_columns(), opt),
              path + ": /entry attribute \"NX_class\" is given twice or reserved");
    opt = {};
    opt.logs = {{"data", "", ""}};
    EXPECT_EQ(error(three_columns(), opt), path + ": log name \"data\" is not a new group name under /entry");
    opt.logs = {{"ds0", "", ""}, {"ds0", "", ""}};
    EXPECT_EQ(error(three_columns(), opt), path + ": log name \"ds0\" is not a new group name under /entry");
    opt = {};
    opt.chunk_rows = 0;
    EXPECT_EQ(error(three_columns(), opt), path + ": chunk_rows 0 should be >= 1");
    EXPECT_FALSE(std::filesystem::exists(path));
}

// A column of width w (an oversampled input's samples a cycle) is one [rows, w] dataset that takes
// w consecutive values of each row, in order; the columns after it keep theirs.
TEST(NexusFile, AWideColumnIsATwoDimensionalDataset) {
    TempDir dir;
    const std::string path = dir.file("wide.h5");
    std::vector<NexusColumn> columns = three_columns();
    NexusColumn ai{"ai", "counts", "ec0.s7.mm.analogInputArray01", "Value"};
    ai.width = 4;
    columns.insert(columns.begin() + 1, ai);
    NexusOptions opt;
    opt.chunk_rows = 8; // 2 rows a chunk of the wide dataset
    NexusFile f(path, columns, opt);
    EXPECT_EQ(f.columns(), 3u + 4u);
    append_rows(f, 0, 5);
    append_rows(f, 5, 6);
    f.close();
    Id file{H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose};
    ASSERT_GE(file.id, 0);
    Id ds{H5Dopen2(file.id, "/entry/data/ai", H5P_DEFAULT), H5Dclose};
    ASSERT_GE(ds.id, 0);
    Id space{H5Dget_space(ds.id), H5Sclose};
    ASSERT_EQ(H5Sget_simple_extent_ndims(space.id), 2);
    hsize_t dims[2] = {}, max[2] = {}, chunk[2] = {};
    H5Sget_simple_extent_dims(space.id, dims, max);
    EXPECT_EQ(dims[0], 11u);
    EXPECT_EQ(dims[1], 4u);
    EXPECT_EQ(max[0], H5S_UNLIMITED);
    EXPECT_EQ(max[1], 4u);
    Id dcpl{H5Dget_create_plist(ds.id), H5Pclose};
    ASSERT_EQ(H5Pget_chunk(dcpl.id, 2, chunk), 2);
    EXPECT_EQ(chunk[0], 2u);
    EXPECT_EQ(chunk[1], 4u);
    std::vector<double> v(11 * 4);
    ASSERT_GE(H5Dread(ds.id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()), 0);
    for (uint64_t r = 0; r < 11; ++r)
        for (std::size_t k = 0; k < 4; ++k) EXPECT_EQ(v[r * 4 + k], value(r, 1 + k)) << r << "," << k;
    EXPECT_EQ(attr(file.id, "/entry/data/ai", "source"), "ec0.s7.mm.analogInputArray01");
    Id spr{H5Aopen_by_name(file.id, "/entry/data/ai", "samples_per_row", H5P_DEFAULT, H5P_DEFAULT), H5Aclose};
    int32_t n = 0;
    ASSERT_GE(H5Aread(spr.id, H5T_NATIVE_INT32, &n), 0);
    EXPECT_EQ(n, 4);
    // the 1-D columns around it
    for (auto [name, j] : {std::pair{"ax1_enc_actpos", 0}, {"i0", 5}, {"ax1_velocity", 6}}) {
        Id d{H5Dopen2(file.id, (std::string("/entry/data/") + name).c_str(), H5P_DEFAULT), H5Dclose};
        std::vector<double> c = read_all<double>(d.id, H5T_NATIVE_DOUBLE);
        ASSERT_EQ(c.size(), 11u) << name;
        for (uint64_t r = 0; r < 11; ++r) EXPECT_EQ(c[r], value(r, std::size_t(j))) << name << " row " << r;
    }
}

TEST(NexusFile, CloseIsIdempotentAndAppendAfterItThrows) {
    TempDir dir;
    NexusFile f(dir.file("scan.h5"), three_columns());
    append_rows(f, 0, 2);
    f.close();
    f.close();
    EXPECT_THROW(append_rows(f, 2, 1), Error);
    EXPECT_THROW(f.flush(), Error);
    EXPECT_EQ(f.rows(), 2u);
}

TEST(NexusFile, AppendAllocatesNothingAfterTheFirst) {
    TempDir dir;
    const std::size_t ncol = 64, n = 100;
    std::vector<NexusColumn> columns;
    for (std::size_t j = 0; j < ncol; ++j) columns.push_back({std::to_string(j), "", "", "Value"});
    NexusFile f(dir.file("scan.h5"), columns);
    std::vector<uint64_t> cycle(n), t(n);
    std::vector<double> v(n * ncol, 1.5);
    f.append(cycle.data(), t.data(), v.data(), n);
    beamctl::test::count_allocations(true);
    for (int k = 0; k < 20; ++k) f.append(cycle.data(), t.data(), v.data(), k % 2 ? n : n / 3);
    f.flush();
    beamctl::test::count_allocations(false);
    EXPECT_EQ(beamctl::test::allocations(), 0);
    EXPECT_EQ(f.rows(), n + 10 * n + 10 * (n / 3));
}
