// Fly scans in an IOC (docs/flyscan.md): the position-compare blocks of `pcomp:` (daq::Pcomp, PandA's
// PCOMP) and the capture of `capture:` (daq::Capture and its writer thread, PandA's PCAP), run in
// the Triggers stage of the cycle (after the axes and PLCs, before bus send: a block's OUT leaves
// on its output bit in the same cycle's frame) and served with PandA's field names:
//   $(P)PCOMP<n>:ENABLE, INP (the engine signal compared, a put rebinds it), PRE_START, START,
//     WIDTH, STEP, PULSES, RELATIVE, DIR, ACTIVE, OUT, PRODUCED, HEALTH, STATE, POSN (INP now),
//     TIMED (edges sent to a DC-timestamped output or placed in an oversampled one), LATE (edges
//     too late for the timestamped output)
//   $(P)PCAP:ARM, DISARM, ACTIVE, FILE_PATH, FILE_NAME (where the next file goes), FULL_FILE_NAME,
//     CAPTURE (number of the last capture), ROWS_CAPTURED, ROWS_WRITTEN, ROWS_DROPPED, FILES,
//     STATUS (text), ERROR, LAST:<column> and LAST:CYCLE (the last rows, for live plots)
// Signals: pcomp<n>.out, .active, .produced (records and capture fields read them); capture fields
// and triggers also take pcomp<n>.rose (1 in the cycle OUT rose). A capture field may name a memory
// map (ec0.s7.mm.analogInputArray01: an oversampled channel's n samples a cycle): n values a row,
// one [rows, n] dataset in the file. The data storages of capture.storages write every value PLC
// code appends while a capture runs into its file (/entry/ds<n>, NXlog).
// Threading: construction and bind() before the cycle starts; the stage on the RT thread; puts,
// publish() and stop() on the IOC loop; the capture's HDF5 writing on its own writer thread.
#pragma once

#include "config/ioc_config.hpp"
#include "core/spsc_queue.hpp"
#include "daq/capture.hpp"
#include "daq/capture_writer.hpp"
#include "daq/pcomp.hpp"
#include "daq/timed_output.hpp"
#include "ethercat/bus.hpp"
#include "ioc/memmaps.hpp"
#include "module/value_source.hpp"
#include "motion/axis_group.hpp"
#include "plc/program.hpp"
#include "pv/database.hpp"
#include "pv/link.hpp"
#include "registry/registry.hpp"
#include "rt/engine.hpp"

#include <atomic>
#include <memory>
#include <string>
#include <vector>

namespace beamctl::ioc {

class IocFlyScan {
public:
    // Declares the blocks' signals and makes their records (loaded into `db`); `memmaps`: the
    // IOC's memory maps, which capture fields may name.
    IocFlyScan(const config::IocConfig& cfg, registry::Registry& reg, pv::Database& db, const IocMemMaps* memmaps = nullptr);
    ~IocFlyScan();
    IocFlyScan(const IocFlyScan&) = delete;
    IocFlyScan& operator=(const IocFlyScan&) = delete;

    bool enabled() const { return !blocks_.empty() || cfg_.capture.has_value(); }
    // Bring-up: binds inputs, outputs, capture fields; adds the stage. Throws Error (file:line:col).
    // An output on an EL2252 channel (a slave with startTime and activate) gets its edges at their
    // predicted DC times (daq::TimedPcompOutput); it needs a bus this IOC masters (`buses`).
    // `storages`: the IOC's data storages (capture.storages names some of them).
    void bind(rt::Engine& engine, motion::AxisGroup* axes, const std::vector<ethercat::Bus*>& buses = {},
              const std::vector<daq::DataStorage*>& storages = {});
    // IOC loop: the blocks' and the capture's state into the PVs.
    void publish();
    // Clean stop: ends a running capture (its file is completed).
    void stop();

    // Tests: the blocks and the capture.
    std::size_t blocks() const { return blocks_.size(); }
    const daq::Pcomp& pcomp(std::size_t i) const { return blocks_.at(i)->pc; }
    const daq::TimedPcompOutput* timed_output(std::size_t i) const { return blocks_.at(i)->timed.get(); }
    const daq::OversampledPcompOutput* oversampled_output(std::size_t i) const { return blocks_.at(i)->over.get(); }
    daq::Capture* capture() { return capture_.get(); }
    daq::CaptureWriter* writer() { return writer_.get(); }
    // PLC code's names of the blocks (pcomp<n>.enable, .start, ... .out, .state): the cells the
    // cycle reads before and writes after each block's evaluation; nullopt for other names.
    std::optional<plc::Binding> plc_cell(const std::string& name);
    // Device support "beamctl" on a block's signals (INP "@pcomp1.out", ".active", ".produced"):
    // read in the IOC loop; nullptr with `why` for anything else (writes: the PCOMP PVs).
    std::unique_ptr<pv::LinkDevice> make_device(std::string_view name, int bit, bool output, std::string& why);
    // The path the next ARM writes (FILE_PATH/FILE_NAME with the capture number).
    std::string next_file() const;

private:
    struct Block {
        config::PcompEntry cfg;
        daq::Pcomp pc;
        module::ValueSource inp;
        registry::BoundSignal out;
        // a DC-timestamped output (EL2252): its slave's startTime and activate, and its bus
        std::string timed_prefix; // "ec0.s4." when the output is one
        std::unique_ptr<daq::TimedPcompOutput> timed;
        // an analog output: its samples (one, or an EL4732's n per cycle: placed by `over`)
        std::vector<std::string> sample_names;
        std::vector<registry::BoundSignal> samples;
        std::unique_ptr<daq::OversampledPcompOutput> over;
        registry::BoundSignal start_time, activate;
        ethercat::Bus* bus = nullptr;
        // IOC loop -> RT: the whole wanted state (parameters, enable, input) after each put
        struct Cmd {
            daq::PcompParams params;
            bool enable = false;
            module::ValueSource inp;
        };
        Cmd want;
        SpscQueue<Cmd> cmds{64};
        // The block as PLC code sees it (RT thread): parameters PLC code and PV puts write, read
        // by the cycle before each evaluation; results written after it.
        enum Cell { Enable, Start, Step, Width, Pulses, PreStart, Relative, Dir, Out, Active, Produced, Health, State, kCells };
        static constexpr int kParams = Out; // cells before Out are writable
        double cell[kCells] = {};
        std::atomic<double> st_param[kParams] = {}; // the parameters as the cycle last used them
        double seen_param[kParams] = {};            // IOC loop: as publish() last saw them
        // RT -> IOC loop
        std::atomic<uint32_t> st_out{0}, st_active{0}, st_produced{0}, st_health{0}, st_state{0};
        std::atomic<double> st_posn{0};
        std::atomic<uint64_t> st_timed{0}, st_late{0};
        pv::Record *enable_r = nullptr, *inp_r = nullptr, *pre_start = nullptr, *start = nullptr, *width = nullptr, *step = nullptr,
                   *pulses = nullptr, *relative = nullptr, *dir = nullptr, *active = nullptr, *out_r = nullptr, *produced = nullptr,
                   *health = nullptr, *state = nullptr, *posn = nullptr, *timed_r = nullptr, *late = nullptr;
    };
    class Stage;
    module::ValueSource resolve(const std::string& name, std::string& why) const;
    void check_names(); // and claims the outputs
    bool send(Block& b);
    static void to_cells(const Block::Cmd& c, double* cell);
    bool arm();
    void set_text(pv::Record* r, const std::string& text);
    std::string text(pv::Record* r) const;
    // The elements of memory map `name` (a capture field of n samples a cycle); nullptr if none.
    const std::vector<std::string>* samples_of(const std::string& name) const;

    config::IocConfig cfg_;
    registry::Registry& reg_;
    pv::Database& db_;
    const IocMemMaps* memmaps_ = nullptr;
    motion::AxisGroup* axes_ = nullptr;
    std::vector<std::unique_ptr<Block>> blocks_;
    // capture
    std::unique_ptr<daq::Capture> capture_;
    std::unique_ptr<daq::CaptureWriter> writer_;
    std::vector<module::ValueSource> fields_;
    module::ValueSource gate_;
    // What captures a row: a block's rising OUT (its edge time stamps the row), every cycle, or
    // a signal's rising edge; any of them.
    struct Trigger {
        int block = -1;  // index in blocks_
        bool cycle = false;
        module::ValueSource sig; // else
        bool level = false; // RT: the signal's last level
    };
    std::vector<Trigger> triggers_;
    std::vector<daq::DataStorage*> taps_; // capture.storages: told each cycle which capture runs
    std::vector<std::string> columns_;
    pv::Record *arm_ = nullptr, *disarm_ = nullptr, *cap_active_ = nullptr, *file_path_ = nullptr, *file_name_ = nullptr,
               *full_name_ = nullptr, *capture_no_ = nullptr, *rows_captured_ = nullptr, *rows_written_ = nullptr,
               *rows_dropped_ = nullptr, *files_ = nullptr, *status_ = nullptr, *error_ = nullptr, *last_cycle_ = nullptr;
    // LAST:<column>, one per file column: Capture columns col .. col + width - 1 (a memory map's
    // samples, row by row); u64: bit patterns of uint64 values
    struct LastPv {
        pv::Record* r = nullptr;
        std::size_t col = 0, width = 1;
        bool u64 = false;
    };
    std::vector<LastPv> last_;
    uint64_t status_version_ = ~uint64_t(0);
    std::vector<double> scratch_;
    std::unique_ptr<Stage> stage_;
};

} // namespace beamctl::ioc
