// Soft PLC evaluation cost: one scan of the kinematics examples (examples/kinematics/mirror.plc
// and mirror_matrix.plc, both states; spiral.plc), a generated 100-statement PLC, and each of
// the mirror's ten output expressions (five jacks from the pose, five pose values from the
// jacks) written out as one expression over bound variables and evaluated by our PLC
// (`r := <expr>;`, one scan) and, when built with BEAMCTL_BENCH_MUPARSER, by muparser
// (Parser::Eval) with the same variables bound, and, when built with BEAMCTL_BENCH_EXPRTK, by
// ExprTk as ECMC runs it (exprtk_reference.hpp): every expression and every scan, with a
// `bit_equal` counter saying whether ExprTk's results equal beamctl's bit for bit. Issue targets:
// faster than muparser (issue 9) and than ExprTk (issue 18) on every expression and scan.
#include "daq/data_storage.hpp"
#include "plc/program.hpp"
#include "plc/runtime.hpp"

#include <benchmark/benchmark.h>

#ifdef BEAMCTL_BENCH_MUPARSER
#include <muParser.h>
#endif
#ifdef BEAMCTL_BENCH_EXPRTK
#include "exprtk_reference.hpp"
#include "plc/source.hpp"
#endif

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

using beamctl::plc::Binding;
using beamctl::plc::CompileOptions;
using beamctl::plc::Host;
using beamctl::plc::Program;

namespace {

const std::filesystem::path kExamples =
    std::filesystem::path(__FILE__).parent_path().parent_path() / "examples";

// Every name is a double of its own, created on first use.
class MapHost : public Host {
public:
    double& operator[](const std::string& name) { return vars_[name]; }
    const std::map<std::string, double>& vars() const { return vars_; }
    std::optional<Binding> resolve(std::string_view name) override {
        return Binding{&vars_[std::string(name)], true, 1};
    }

private:
    std::map<std::string, double> vars_;
};

// ---- the mirror's output expressions (default geometry of mirror_trig.plc_inc) ---------------

std::string replace_all(std::string s, const std::string& from, const std::string& to) {
    for (std::size_t p = s.find(from); p != std::string::npos; p = s.find(from, p + to.size()))
        s.replace(p, from.size(), to);
    return s;
}

// Expands the upper-case placeholders, innermost last.
std::string expand(std::string e) {
    const std::pair<const char*, const char*> defs[] = {
        {"CY_", "((P_ + SX * Q_) / (1 - SX * TY))"},
        {"P_", "((yui + yuo) / 2 - 50 + SZ * 400 + 50 * NN)"},
        {"Q_", "(xu - 60 + TY * 25 + TZ * 400 + 60 * MM)"},
        {"NN", "sqrt(1 + SX ^ 2 + SZ ^ 2)"},
        {"MM", "sqrt(1 + TY ^ 2 + TZ ^ 2)"},
        {"TY", "(SZ * TZ - SX)"},
        {"SX", "((yui - yuo) / 300)"},
        {"SZ", "((yd - (yui + yuo) / 2) / 800)"},
        {"TZ", "((xd - xu) / 800)"},
        {"NX", "(sin(yaw / 1000) * sin(pitch / 1000) * cos(roll / 1000) - cos(yaw / 1000) * "
               "sin(roll / 1000))"},
        {"NY", "(cos(pitch / 1000) * cos(roll / 1000))"},
        {"NZ", "(sin(yaw / 1000) * sin(roll / 1000) + cos(yaw / 1000) * sin(pitch / 1000) * "
               "cos(roll / 1000))"},
        {"MX", "(cos(yaw / 1000) * cos(roll / 1000) + sin(yaw / 1000) * sin(pitch / 1000) * "
               "sin(roll / 1000))"},
        {"MY", "(cos(pitch / 1000) * sin(roll / 1000))"},
        {"MZ", "(cos(yaw / 1000) * sin(pitch / 1000) * sin(roll / 1000) - sin(yaw / 1000) * "
               "cos(roll / 1000))"},
    };
    for (const auto& [name, text] : defs) e = replace_all(e, name, text);
    return e;
}

struct Expr {
    const char* name;
    std::string text;
};

const std::vector<Expr>& mirror_exprs() {
    static const std::vector<Expr> exprs = {
        {"inv_YUI", expand("cy + (NX * (cx - 150) + NZ * 400 - 50) / NY + 50")},
        {"inv_YUO", expand("cy + (NX * (cx + 150) + NZ * 400 - 50) / NY + 50")},
        {"inv_YD", expand("cy + (NX * cx - NZ * 400 - 50) / NY + 50")},
        {"inv_XU", expand("cx + (MY * (cy + 25) + MZ * 400 - 60) / MX + 60")},
        {"inv_XD", expand("cx + (MY * (cy + 25) - MZ * 400 - 60) / MX + 60")},
        {"fwd_PITCH", expand("1000 * atan2(-(SZ + SX * TZ), sqrt((TY * NN) ^ 2 + (MM) ^ 2))")},
        {"fwd_YAW", expand("1000 * atan2(TZ + TY * SZ, 1 - SX * TY)")},
        {"fwd_ROLL", expand("1000 * atan2(-TY * NN, MM)")},
        {"fwd_CX", expand("Q_ + TY * CY_")},
        {"fwd_CY", expand("CY_")},
    };
    return exprs;
}

// A pose of 3, -4, 5 mrad, 6, -7 mm and jack positions near it.
const std::pair<const char*, double> kInputs[] = {
    {"pitch", 3}, {"yaw", -4}, {"roll", 5},    {"cx", 6},    {"cy", -7},
    {"xu", 7.3},  {"xd", 3.9}, {"yui", -4.8}, {"yuo", -6.4}, {"yd", -9.4}};

void BM_Expr_beamctl(benchmark::State& state) {
    const Expr& e = mirror_exprs()[std::size_t(state.range(0))];
    state.SetLabel(e.name);
    MapHost h;
    for (const auto& [n, v] : kInputs) h[n] = v;
    Program p = Program::compile("r := " + e.text + ";", "expr.plc", h);
    double& r = h["r"];
    for (auto _ : state) {
        if (p.run() != 0) state.SkipWithError("scan failed");
        benchmark::DoNotOptimize(r);
    }
    state.counters["instructions"] = double(p.size());
}
BENCHMARK(BM_Expr_beamctl)->DenseRange(0, 9);

#ifdef BEAMCTL_BENCH_MUPARSER
void BM_Expr_muparser(benchmark::State& state) {
    const Expr& e = mirror_exprs()[std::size_t(state.range(0))];
    state.SetLabel(e.name);
    std::map<std::string, double> vars;
    mu::Parser parser;
    for (const auto& [n, v] : kInputs) {
        vars[n] = v;
        parser.DefineVar(n, &vars[n]);
    }
    parser.SetExpr(e.text);
    double r = parser.Eval(); // compiles to bytecode on the first Eval
    for (auto _ : state) {
        r = parser.Eval();
        benchmark::DoNotOptimize(r);
    }
}
BENCHMARK(BM_Expr_muparser)->DenseRange(0, 9);
#endif

#ifdef BEAMCTL_BENCH_EXPRTK
bool same_bits(double a, double b) {
    return std::memcmp(&a, &b, sizeof a) == 0;
}

// 1 when every variable both engines hold has the same bits.
double agree(const std::map<std::string, double>& ours, const std::map<std::string, double>& theirs) {
    for (const auto& [name, v] : theirs)
        if (auto it = ours.find(name); it != ours.end() && !same_bits(it->second, v)) {
            std::fprintf(stderr, "ExprTk differs on %s: %.17g vs beamctl %.17g\n", name.c_str(), v, it->second);
            return 0;
        }
    return 1;
}

std::unique_ptr<exprtk_reference::Expression> exprtk_compile(const std::string& text,
                                                             std::map<std::string, double>& vars) {
    std::string error;
    auto e = exprtk_reference::Expression::compile(text, vars, error);
    if (!e) throw std::runtime_error("ExprTk refuses the code: " + error);
    return e;
}

void BM_Expr_exprtk(benchmark::State& state) {
    const Expr& e = mirror_exprs()[std::size_t(state.range(0))];
    state.SetLabel(e.name);
    std::map<std::string, double> vars;
    MapHost h;
    for (const auto& [n, v] : kInputs) vars[n] = h[n] = v;
    const std::string code = "r := " + e.text + ";";
    auto x = exprtk_compile(code, vars);
    Program p = Program::compile(code, "expr.plc", h);
    for (auto _ : state) benchmark::DoNotOptimize(x->value());
    p.run();
    state.counters["bit_equal"] = agree(h.vars(), vars);
}
BENCHMARK(BM_Expr_exprtk)->DenseRange(0, 9);
#endif

// ---- whole scans --------------------------------------------------------------------------------

// The axes of a shipped kinematics PLC at a pose; `busy` puts it in state 1 (inverse running).
template <typename Vars> void set_pose(Vars& v, const char* busy_axis) {
    const double jacks[] = {7.3, 3.9, -4.8, -6.4, -9.4};
    for (int j = 0; j < 5; ++j) {
        v["ax" + std::to_string(j + 1) + ".enc.actpos"] = jacks[j];
        v["ax" + std::to_string(j + 1) + ".traj.setpos"] = jacks[j];
        v["ax" + std::to_string(j + 6) + ".traj.setpos"] = kInputs[j].second;
    }
    if (busy_axis) v[std::string(busy_axis) + ".traj.busy"] = 1;
}

CompileOptions example_options() {
    CompileOptions o;
    o.macros = {{"SELF", "plc0"}, {"SELF_ID", "0"}};
    o.include_path = {(kExamples / "plc_lib").string()};
    return o;
}

void scan_example(benchmark::State& state, const char* file, const char* busy_axis) {
    MapHost h;
    Program p = Program::compile_file((kExamples / "kinematics" / file).string(), h, example_options());
    set_pose(h, busy_axis);
    for (int i = 0; i < 2; ++i) p.run(); // first scan, state change
    for (auto _ : state) {
        if (p.run() != 0) state.SkipWithError("scan failed");
        benchmark::ClobberMemory();
    }
    state.counters["instructions"] = double(p.size());
}
void BM_Scan_mirror_trig_S1(benchmark::State& s) { scan_example(s, "mirror.plc", "ax6"); }
void BM_Scan_mirror_trig_S0(benchmark::State& s) { scan_example(s, "mirror.plc", nullptr); }
void BM_Scan_mirror_matrix_S1(benchmark::State& s) { scan_example(s, "mirror_matrix.plc", "ax6"); }
void BM_Scan_mirror_matrix_S0(benchmark::State& s) { scan_example(s, "mirror_matrix.plc", nullptr); }
void BM_Scan_spiral_S1(benchmark::State& s) { scan_example(s, "spiral.plc", "ax3"); }
BENCHMARK(BM_Scan_mirror_trig_S1);
BENCHMARK(BM_Scan_mirror_trig_S0);
BENCHMARK(BM_Scan_mirror_matrix_S1);
BENCHMARK(BM_Scan_mirror_matrix_S0);
BENCHMARK(BM_Scan_spiral_S1);

#ifdef BEAMCTL_BENCH_EXPRTK
// The same scans by ExprTk: the file preprocessed as ecmccfg does (macros, includes, `#`
// comments), as ECMC hands it to ExprTk.
std::string preprocessed(const std::string& path) {
    namespace d = beamctl::plc::detail;
    d::Diagnostics diags(10);
    d::Source src;
    beamctl::MacroMap macros = example_options().macros;
    d::preprocess(src, d::read_file(path), path, macros, example_options().include_path, diags);
    if (!diags.empty()) throw std::runtime_error(diags.messages().front());
    std::string text;
    for (const d::SourceLine& l : src.lines) text += l.text + "\n";
    return text;
}

void scan_example_exprtk(benchmark::State& state, const char* file, const char* busy_axis) {
    const std::string path = (kExamples / "kinematics" / file).string();
    std::map<std::string, double> vars;
    auto x = exprtk_compile(preprocessed(path), vars);
    set_pose(vars, busy_axis);
    for (int i = 0; i < 2; ++i) x->value();
    for (auto _ : state) {
        benchmark::DoNotOptimize(x->value());
        benchmark::ClobberMemory();
    }
    // beamctl from the same pose, as many scans: the same values?
    MapHost h;
    Program p = Program::compile_file(path, h, example_options());
    set_pose(h, busy_axis);
    for (benchmark::IterationCount i = 0; i < state.iterations() + 2; ++i) p.run();
    state.counters["bit_equal"] = agree(h.vars(), vars);
}
void BM_Scan_mirror_trig_S1_exprtk(benchmark::State& s) { scan_example_exprtk(s, "mirror.plc", "ax6"); }
void BM_Scan_mirror_trig_S0_exprtk(benchmark::State& s) { scan_example_exprtk(s, "mirror.plc", nullptr); }
void BM_Scan_mirror_matrix_S1_exprtk(benchmark::State& s) { scan_example_exprtk(s, "mirror_matrix.plc", "ax6"); }
void BM_Scan_mirror_matrix_S0_exprtk(benchmark::State& s) { scan_example_exprtk(s, "mirror_matrix.plc", nullptr); }
void BM_Scan_spiral_S1_exprtk(benchmark::State& s) { scan_example_exprtk(s, "spiral.plc", "ax3"); }
BENCHMARK(BM_Scan_mirror_trig_S1_exprtk);
BENCHMARK(BM_Scan_mirror_trig_S0_exprtk);
BENCHMARK(BM_Scan_mirror_matrix_S1_exprtk);
BENCHMARK(BM_Scan_mirror_matrix_S0_exprtk);
BENCHMARK(BM_Scan_spiral_S1_exprtk);
#endif

// 100 statements in four kinds, 25 of each: arithmetic, math functions, if/else, min/max with a
// comparison; over 2 inputs and 100 statics, each reading an earlier result.
std::string hundred_statements() {
    std::string code;
    char line[256];
    for (int i = 0; i < 100; ++i) {
        const int j = (i * 37 + 11) % 100;
        switch (i % 4) {
        case 0:
            std::snprintf(line, sizeof line, "static.v%d := static.v%d * 1.5 + x - 2;\n", i, j);
            break;
        case 1:
            std::snprintf(line, sizeof line,
                          "static.v%d := sin(static.v%d) * cos(x) + sqrt(abs(y));\n", i, j);
            break;
        case 2:
            std::snprintf(line, sizeof line,
                          "if (static.v%d > x) { static.v%d := static.v%d - 1; } else { "
                          "static.v%d := y; };\n",
                          j, i, j, i);
            break;
        default:
            std::snprintf(line, sizeof line,
                          "static.v%d := max(static.v%d, y) / (1 + abs(x)) + (x < y);\n", i, j);
        }
        code += line;
    }
    return code;
}

void BM_Scan_100_statements(benchmark::State& state) {
    MapHost h;
    h["x"] = 0.25;
    h["y"] = -1.5;
    Program p = Program::compile(hundred_statements(), "hundred.plc", h);
    for (auto _ : state) {
        if (p.run() != 0) state.SkipWithError("scan failed");
        benchmark::ClobberMemory();
    }
    state.counters["instructions"] = double(p.size());
    state.counters["ns_per_statement"] = benchmark::Counter(
        100 * double(state.iterations()), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_Scan_100_statements);

#ifdef BEAMCTL_BENCH_EXPRTK
void BM_Scan_100_statements_exprtk(benchmark::State& state) {
    std::map<std::string, double> vars;
    vars["x"] = 0.25;
    vars["y"] = -1.5;
    auto x = exprtk_compile(hundred_statements(), vars);
    for (auto _ : state) {
        benchmark::DoNotOptimize(x->value());
        benchmark::ClobberMemory();
    }
    MapHost h;
    h["x"] = 0.25;
    h["y"] = -1.5;
    Program p = Program::compile(hundred_statements(), "hundred.plc", h);
    for (benchmark::IterationCount i = 0; i < state.iterations(); ++i) p.run();
    state.counters["bit_equal"] = agree(h.vars(), vars);
}
BENCHMARK(BM_Scan_100_statements_exprtk);
#endif

// ---- data storage (issue 13: "data storage append per value") ----------------------------------

// The buffer alone: one value appended to a 1000-value ring (arg 1) or FIFO (arg 2).
void BM_DsAppend_buffer(benchmark::State& state) {
    beamctl::daq::DataStorage d(0, 1000, beamctl::daq::BufferType(state.range(0)));
    double v = 0;
    for (auto _ : state) {
        d.append(v);
        v += 1;
        benchmark::ClobberMemory();
    }
}
BENCHMARK(BM_DsAppend_buffer)->Arg(1)->Arg(2);

// From PLC code, in a PlcRuntime scan: 100 `ds_append_data(0, v)` calls (arg 0), or one
// `ds0.append := v` (arg 1: the variable's per-scan read and write-back included); per value.
void BM_DsAppend_plc(benchmark::State& state) {
    beamctl::daq::DataStorage d(0, 1000, beamctl::daq::BufferType::Ring);
    beamctl::plc::PlcRuntime::Options o;
    o.storages = {&d};
    beamctl::plc::PlcRuntime rt(o);
    beamctl::plc::PlcSource src;
    src.file = "ds.plc";
    const bool by_variable = state.range(0) == 1;
    const int per_scan = by_variable ? 1 : 100;
    if (by_variable) {
        src.text = "static.v += 1;\nds0.append := static.v;\n";
    } else {
        for (int i = 0; i < per_scan; ++i) src.text += "ds_append_data(0, static.v + " + std::to_string(i) + ");\n";
        src.text += "static.v += 1;\n";
    }
    rt.add(src);
    uint64_t cycle = 0;
    for (auto _ : state) {
        rt.run(beamctl::rt::CycleInfo{cycle++, 0, 1000000});
        benchmark::ClobberMemory();
    }
    if (d.appended() != uint64_t(per_scan) * cycle) state.SkipWithError("values were lost");
    state.counters["ns_per_value"] = benchmark::Counter(double(per_scan) * double(state.iterations()),
                                                        benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_DsAppend_plc)->Arg(0)->Arg(1);

// Memory maps (an EL3702 channel at oversampling 100: 100 INT16 samples), from PLC code: one
// `ec_mm_append_to_ds(0, 0)` per scan (arg 0) or a loop of 100 `ec_get_mm_data(0, i)` (arg 1);
// per sample.
void BM_MemMap_plc(benchmark::State& state) {
    std::vector<uint8_t> image(256, 0);
    for (int i = 0; i < 100; ++i) image[std::size_t(2 * i)] = uint8_t(i);
    beamctl::registry::MemMap mm;
    mm.name = "ec0.s1.mm.analogInputArray01";
    mm.first = beamctl::registry::BoundSignal{image.data(), 0, 16, true, -1};
    mm.count = 100;
    mm.type = beamctl::registry::ecmc_data_type("INT16");
    beamctl::daq::DataStorage d(0, 1000, beamctl::daq::BufferType::Ring);
    beamctl::plc::PlcRuntime::Options o;
    o.storages = {&d};
    o.memmaps = {&mm};
    beamctl::plc::PlcRuntime rt(o);
    beamctl::plc::PlcSource src;
    src.file = "mm.plc";
    src.text = state.range(0) == 0 ? "ec_mm_append_to_ds(0, 0);\n"
                                   : "static.s := 0;\nfor (var i := 0; i < 100; i += 1) { static.s += ec_get_mm_data(0, i); };\n";
    rt.add(src);
    uint64_t cycle = 0;
    for (auto _ : state) {
        rt.run(beamctl::rt::CycleInfo{cycle++, 0, 1000000});
        benchmark::ClobberMemory();
    }
    if (state.range(0) == 0 && d.appended() != 100 * cycle) state.SkipWithError("values were lost");
    state.counters["ns_per_sample"] = benchmark::Counter(100.0 * double(state.iterations()),
                                                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_MemMap_plc)->Arg(0)->Arg(1);

} // namespace

int main(int argc, char** argv) {
#ifndef BEAMCTL_BENCH_EXPRTK
    std::fprintf(stderr, "bench_plc: the ExprTk reference was not measured (configure with "
                         "-DBEAMCTL_EXPRTK_DIR=<directory holding exprtk.hpp>)\n");
#endif
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
