// One EtherCAT bus in a running IOC: the master, its link, the RT stages that exchange process data, the snapshot the cycle publishes for
// non-RT readers and the queue of output writes coming from them.
// Threading: stages run on the RT thread; write()/snapshot() on ONE non-RT thread (the IOC loop).
#pragma once

#include "core/spsc_queue.hpp"
#include "core/triple_buffer.hpp"
#include "ethercat/master.hpp"
#include "rt/engine.hpp"

#include <memory>
#include <thread>
#include <vector>

namespace beamctl::ethercat {

struct BusSnapshot {
    std::vector<uint8_t> image; // process image after the cycle's receive (outputs as sent)
    uint64_t cycle = 0;
    uint16_t wkc = 0, expected_wkc = 0;
    uint64_t frames_lost = 0, frames_late = 0, wkc_errors = 0;
    bool link_up = false;   // the last cyclic frame came back
    bool wkc_ok = false;    // the last WKC was the one the slaves taking part give (Master::cycle_ok)
    int responding = -1;    // slaves answering the cycle's broadcast read
    std::vector<uint8_t> slave_valid;  // per configured slave: its data took part in the cycle, in OP
    std::vector<uint8_t> slave_al;     // per configured slave: AL status (state | 0x10 error)
    std::vector<uint8_t> slave_online; // per configured slave: answered its last status poll
    std::vector<uint32_t> changes;     // per watch (Bus::watch): cycles in which the entry changed
};

struct OutputWrite {
    uint32_t bit_offset = 0;
    uint8_t bits = 0;
    uint64_t value = 0;
};

// RT: compares n watched entries of `image` with their values of the previous cycle (`last`),
// counts a change for each that differs and returns whether any did. The change watch of a Bus's
// publish stage (and of bench/bench_io_intr, which measures it alone).
bool detect_changes(const uint8_t* image, const uint32_t* bit_offset, const uint8_t* bits, uint64_t* last,
                    uint32_t* changes, std::size_t n) noexcept;

class Bus {
public:
    // The master code never depends on the simulator: an in-process segment behind `link` is
    // owned by whoever assembles the IOC.
    Bus(int id, std::unique_ptr<Link> link, std::vector<SlaveConfig> slaves, const Catalog& catalog);
    ~Bus();

    void bring_up(); // non-RT, before the engine starts; throws Error
    void add_stages(rt::Engine& e);
    // Starts the non-RT health thread (once the RT cycle runs): lost slaves are reported and
    // brought back to OP when they return, using acyclic datagrams carried by the cycle.
    void start_health(double period_s = 0.1);
    void stop_health();

    // Non-RT: queue an output write for the next cycle. False if the queue is full.
    bool write(const SignalInfo& s, uint64_t value) noexcept;
    // Non-RT: the latest published snapshot (refreshed if a newer one exists).
    const BusSnapshot& snapshot() noexcept;
    // Non-RT: the snapshot the last snapshot() call took, not refreshed. The IOC loop refreshes
    // once per look (Ioc::publish, a change wake-up) and every record of that look reads this, so
    // that records processed together see the same cycle.
    const BusSnapshot& looked() const noexcept { return snap_.read_buffer(); }

    // Change watches (SCAN "I/O Intr" of records on bus entries): the cycle compares each watched
    // entry with its value of the previous cycle and counts the cycles in which it changed
    // (BusSnapshot::changes), so a change that reverts before the IOC loop looks is still seen;
    // and it wakes the IOC loop through change_fd() at most once per time the loop drains it.
    // watch() is non-RT, after bring_up() and before the cycle starts (-1 after: the caller falls
    // back to comparing values); same entry, same index.
    int watch(const SignalInfo& s);
    void freeze_watches() { watches_frozen_ = true; }
    std::size_t watch_count() const { return watch_offset_.size(); }
    // Readable (eventfd) when a watched entry changed; the IOC loop calls drain_changes() then scans.
    int change_fd() const { return change_fd_; }
    void drain_changes() noexcept;
    uint64_t writes_dropped() const { return writes_dropped_.load(); }

    // The bus as its users (the IOC, its records, axes and PLCs) see it; the master behind it is
    // not theirs to reach (a scanner client will stand behind the same calls). Non-RT; the layout
    // (slaves, signals, bus_bytes) is fixed once bring_up() returned.
    const std::vector<SlaveInfo>& slaves() const { return master_->slaves(); }
    const std::vector<SignalInfo>& signals() const { return master_->signals(); }
    const SignalInfo* find_signal(std::string_view name) const { return master_->find_signal(name); }
    // A signal bound to the image the cycle exchanges (RT code reads and writes it).
    registry::BoundSignal bind(std::string_view name, int bit = -1) { return master_->bind(name, bit); }
    std::size_t bus_bytes() const { return master_->bus_bytes(); } // exchanged with the slaves (then the master's own words)
    SlaveHealth slave_health(std::size_t i) const { return master_->slave_health(i); }
    std::string slave_last_error(std::size_t i) const { return master_->slave_last_error(i); }
    uint64_t health_version() const { return master_->health_version(); }
    // Before bring_up(): refuse to start with a configured slave missing or failing.
    void set_strict(bool strict) { master_->set_strict(strict); }
    // Shutdown, while the cycle still runs: the slaves taking part to SAFEOP.
    void to_safe_op() { master_->to_safe_op(); }

    // The master itself: for this bus's stages and for tests of the master's own behaviour.
    Master& master() { return *master_; }
    int id() const { return id_; }
    const char* link_kind() const { return link_->kind(); }

    static uint64_t get(const std::vector<uint8_t>& image, const SignalInfo& s) noexcept;

private:
    struct ReceiveStage;
    struct SendStage;
    struct PublishStage;
    void apply_writes() noexcept;

    int id_;
    std::unique_ptr<Link> link_;
    std::unique_ptr<Master> master_;
    SpscQueue<OutputWrite> writes_{4096};
    std::atomic<uint64_t> writes_dropped_{0};
    TripleBuffer<BusSnapshot> snap_;
    std::unique_ptr<ReceiveStage> receive_;
    std::unique_ptr<SendStage> send_;
    std::unique_ptr<PublishStage> publish_;
    CycleStatus last_ = CycleStatus::Ok;
    // The change watches, one array per field (the cycle walks them in order): where the entry is,
    // its value in the previous cycle, the cycles in which it changed. Sized before the cycle starts.
    std::vector<uint32_t> watch_offset_;
    std::vector<uint8_t> watch_bits_;
    std::vector<uint64_t> watch_last_;
    std::vector<uint32_t> watch_changes_;    bool watches_frozen_ = false;
    int change_fd_ = -1;
    std::atomic<bool> change_pending_{false}; // RT wrote change_fd_ and the loop has not drained it
    std::thread health_;
    std::atomic<bool> health_stop_{false};
};

} // namespace beamctl::ethercat
