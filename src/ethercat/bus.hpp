// One EtherCAT bus in a running IOC: what stands behind it (BusBackend), the RT stages that exchange process data, the snapshot the cycle publishes for
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
    // A bus run by a scanner (scanner::ClientBackend): attached now, the scanner's last cycle
    // seen, its cycles this IOC never saw (ring drops and time detached), ring drops alone, attaches.
    bool scanner_bus = false, scanner_attached = false;
    uint64_t scanner_cycle = 0, scanner_missed = 0, scanner_drops = 0, scanner_attaches = 0;
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

// What stands behind a Bus: the bus master of this process (LocalBackend: Master + Link), or a
// bus scanner this IOC is a client of (scanner::ClientBackend). Nothing above the Bus knows which.
// The image is laid out as the master lays it out (outputs, inputs, status bytes, then the
// master's own words), so bound signals are offsets into image() either way.
// Threading: receive/send/fill on the RT thread; the rest non-RT (bring-up, the health thread,
// the IOC loop) as marked.
class BusBackend {
public:
    virtual ~BusBackend() = default;
    virtual const char* kind() const noexcept = 0; // "sim", "udp", "raw", "scanner"
    virtual void bring_up() = 0;                   // non-RT, before the cycle; throws Error
    virtual void set_cycle_time_ns(uint64_t ns) = 0;
    virtual void set_strict(bool strict) = 0;
    virtual void to_safe_op() = 0;
    // Layout, fixed once bring_up() returned.
    virtual const std::vector<SlaveInfo>& slaves() const = 0;
    virtual const std::vector<SignalInfo>& signals() const = 0;
    virtual const SignalInfo* find_signal(std::string_view name) const = 0;
    virtual uint8_t* image() noexcept = 0;
    virtual std::size_t image_size() const = 0;
    virtual std::size_t bus_bytes() const = 0;
    // RT: this cycle's inputs into image(); the outputs in image() out; the cycle's status.
    virtual CycleStatus receive(const rt::CycleInfo& c) noexcept = 0;
    virtual void send(const rt::CycleInfo& c) noexcept = 0;
    // RT: everything of the snapshot but the image and the watches.
    virtual void fill(BusSnapshot& s, CycleStatus last) noexcept = 0;
    // Health thread (non-RT): once the cycle runs, then a pass every period or when due.
    virtual void start_cycling() = 0;
    virtual void health_pass() = 0;
    virtual bool health_due() const = 0;
    virtual SlaveHealth slave_health(std::size_t i) const = 0;
    virtual std::string slave_last_error(std::size_t i) const = 0;
    virtual uint64_t health_version() const = 0;
    // Acyclic CoE access (non-RT, while cycling); throw SdoAbort / Error naming bus, slave, object.
    virtual std::vector<uint8_t> sdo_read(int position, uint16_t index, uint8_t sub) = 0;
    virtual void sdo_write(int position, uint16_t index, uint8_t sub, const std::vector<uint8_t>& data) = 0;
    // The cycle this bus imposes on the engine (a scanner's tick), or nullptr: the engine's own.
    virtual rt::TickSource* tick_source() noexcept { return nullptr; }
    virtual uint64_t tick_grace_ns() const noexcept { return 0; }
    // The master of this process, if it is one (tests of the master, the scanner's own buses).
    virtual Master* local_master() noexcept { return nullptr; }
    // RT thread, after receive: the DC reference clock's system time [ns] as the last frame passed
    // it; 0 when this process runs no DC on the bus (no DC slave, or a bus behind a scanner).
    virtual uint64_t dc_time() const noexcept { return 0; }
    // Before bring_up: whether this bus's DC can follow another time base (Master::set_dc_steering);
    // false if it cannot (a bus behind a scanner).
    virtual bool set_dc_steering(bool) { return false; }
    // RT thread, between receive and send: the other time base minus this one [ns], new.
    virtual void steer_dc(int64_t) noexcept {}
};

// The bus master of this process on a link.
class LocalBackend : public BusBackend {
public:
    LocalBackend(int id, std::unique_ptr<Link> link, std::vector<SlaveConfig> slaves, const Catalog& catalog);
    const char* kind() const noexcept override { return link_->kind(); }
    void bring_up() override { master_->bring_up(); }
    void set_cycle_time_ns(uint64_t ns) override { master_->set_cycle_time_ns(ns); }
    void set_strict(bool strict) override { master_->set_strict(strict); }
    void to_safe_op() override { master_->to_safe_op(); }
    const std::vector<SlaveInfo>& slaves() const override { return master_->slaves(); }
    const std::vector<SignalInfo>& signals() const override { return master_->signals(); }
    const SignalInfo* find_signal(std::string_view name) const override { return master_->find_signal(name); }
    uint8_t* image() noexcept override { return master_->image(); }
    std::size_t image_size() const override { return master_->image_size(); }
    std::size_t bus_bytes() const override { return master_->bus_bytes(); }
    CycleStatus receive(const rt::CycleInfo& c) noexcept override;
    void send(const rt::CycleInfo& c) noexcept override;
    void fill(BusSnapshot& s, CycleStatus last) noexcept override;
    void start_cycling() override { master_->start_cycling(); }
    void health_pass() override { master_->check_and_recover(); }
    bool health_due() const override { return master_->health_due(); }
    SlaveHealth slave_health(std::size_t i) const override { return master_->slave_health(i); }
    std::string slave_last_error(std::size_t i) const override { return master_->slave_last_error(i); }
    uint64_t health_version() const override { return master_->health_version(); }
    std::vector<uint8_t> sdo_read(int position, uint16_t index, uint8_t sub) override;
    void sdo_write(int position, uint16_t index, uint8_t sub, const std::vector<uint8_t>& data) override;
    Master* local_master() noexcept override { return master_.get(); }
    uint64_t dc_time() const noexcept override { return master_->dc_reference_time(); }
    bool set_dc_steering(bool on) override {
        master_->set_dc_steering(on);
        return true;
    }
    void steer_dc(int64_t skew_ns) noexcept override { master_->steer_dc(skew_ns); }

private:
    std::unique_ptr<Link> link_;
    std::unique_ptr<Master> master_;
};

class Bus {
public:
    // The master code never depends on the simulator: an in-process segment behind `link` is
    // owned by whoever assembles the IOC.
    Bus(int id, std::unique_ptr<Link> link, std::vector<SlaveConfig> slaves, const Catalog& catalog);
    Bus(int id, std::unique_ptr<BusBackend> backend);
    ~Bus();

    void bring_up(); // non-RT, before the engine starts; throws Error
    // The bus's stages; an engine that follows a scanner's tick is set to it here.
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

    // The bus as its users (the IOC, its records, axes and PLCs) see it; what stands behind it
    // (a master of this process, a scanner) is not theirs to reach. Non-RT; the layout (slaves,
    // signals, bus_bytes) is fixed once bring_up() returned.
    const std::vector<SlaveInfo>& slaves() const { return backend_->slaves(); }
    const std::vector<SignalInfo>& signals() const { return backend_->signals(); }
    const SignalInfo* find_signal(std::string_view name) const { return backend_->find_signal(name); }
    // A signal bound to the image the cycle exchanges (RT code reads and writes it): `bit` >= 0
    // selects one bit. Unbound (image nullptr) if there is no such signal.
    registry::BoundSignal bind(std::string_view name, int bit = -1);
    std::size_t bus_bytes() const { return backend_->bus_bytes(); } // exchanged with the slaves (then the master's own words)
    SlaveHealth slave_health(std::size_t i) const { return backend_->slave_health(i); }
    std::string slave_last_error(std::size_t i) const { return backend_->slave_last_error(i); }
    uint64_t health_version() const { return backend_->health_version(); }
    // Before bring_up(): refuse to start with a configured slave missing or failing.
    void set_strict(bool strict) { backend_->set_strict(strict); }
    // Shutdown, while the cycle still runs: the slaves taking part to SAFEOP.
    void to_safe_op() { backend_->to_safe_op(); }
    // Acyclic CoE access (non-RT, while cycling).
    std::vector<uint8_t> sdo_read(int position, uint16_t index, uint8_t sub) { return backend_->sdo_read(position, index, sub); }
    void sdo_write(int position, uint16_t index, uint8_t sub, const std::vector<uint8_t>& data) {
        backend_->sdo_write(position, index, sub, data);
    }

    // The master itself, when this process runs it: for this bus's tests and the scanner. Throws
    // Error for a bus behind a scanner.
    Master& master();
    BusBackend& backend() { return *backend_; }
    int id() const { return id_; }
    uint64_t dc_time() const noexcept { return backend_->dc_time(); }
    // Before bring_up: this bus's DC follows the time base on the other side of the EL6692 side
    // `slave_prefix` ("ec1.s1.", buses[].dc_follow): each new pair of its time stamps (0x1A02)
    // steers the reference clock by their difference. Throws Error if the bus cannot steer;
    // bring_up throws if the side has no time stamps assigned.
    void follow_dc(const std::string& slave_prefix);
    const char* link_kind() const { return backend_->kind(); }

    static uint64_t get(const std::vector<uint8_t>& image, const SignalInfo& s) noexcept;
    // RT thread, after this cycle's receive stage: how the cycle went.
    CycleStatus last_status() const noexcept { return last_; }

private:
    struct ReceiveStage;
    struct SendStage;
    struct PublishStage;
    void apply_writes() noexcept;

    int id_;
    std::unique_ptr<BusBackend> backend_;
    SpscQueue<OutputWrite> writes_{4096};
    std::atomic<uint64_t> writes_dropped_{0};
    TripleBuffer<BusSnapshot> snap_;
    std::unique_ptr<ReceiveStage> receive_;
    std::unique_ptr<SendStage> send_;
    std::unique_ptr<PublishStage> publish_;
    CycleStatus last_ = CycleStatus::Ok;
    void steer() noexcept; // RT, receive stage
    // follow_dc: the EL6692 side's time stamps and status, the last internal stamp acted on
    const SignalInfo *follow_int_ = nullptr, *follow_ext_ = nullptr, *follow_nc_ = nullptr;
    uint64_t follow_seen_ = 0;
    std::string follow_; // follow_dc's slave prefix ("": none)
    // The change watches, one array per field (the cycle walks them in order): where the entry is,
    // its value in the previous cycle, the cycles in which it changed. Sized before the cycle starts.
    std::vector<uint32_t> watch_offset_;
    std::vector<uint8_t> watch_bits_;
    std::vector<uint64_t> watch_last_;
    std::vector<uint32_t> watch_changes_;
    bool watches_frozen_ = false;
    int change_fd_ = -1;
    std::atomic<bool> change_pending_{false}; // RT wrote change_fd_ and the loop has not drained it
    std::thread health_;
    std::atomic<bool> health_stop_{false};
};

} // namespace beamctl::ethercat
