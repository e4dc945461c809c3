// A simulated EtherCAT segment: ESCs in a line, each frame passing every reachable slave in
// order (as on the wire), with fault injection (unplugged slaves, lost and corrupted frames).
// Terminal behaviour and plant models hook in through on_frame (called after each frame).
#pragma once

#include "core/spsc_queue.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/device.hpp"
#include "ethercat/sim/esc.hpp"
#include "ethercat/sim/faults.hpp"

#include <cstdint>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace beamctl::ethercat::sim {

class Segment {
public:
    static constexpr uint64_t kHopDelayNs = 150; // propagation delay per slave (E-bus + ESC)
    Segment() = default;
    // Appends a slave of this device type at the next position; its SII comes from build_sii.
    Esc& add(const DeviceDesc& desc);
    // Appends the slaves of a configured bus ({position, catalog type}, any order) in position
    // order, an EK1100 in every position not configured (the segment an IOC's or a check's
    // simulated bus has). Throws Error for a type the catalog does not have.
    void add_configured(const std::vector<std::pair<int, std::string>>& slaves, const Catalog& catalog);
    std::size_t size() const { return slaves_.size(); }
    Esc& slave(std::size_t position) { return *slaves_.at(position).esc; }

    // Passes a frame (EtherCAT PDU, in place) through the segment. Returns false if the frame
    // is lost (loss injection); malformed frames come back untouched.
    bool process(uint8_t* frame, std::size_t len) noexcept;

    // Simulated time [ns since 2000-01-01] that slaves see; advanced by the link or tests.
    void set_time(uint64_t ns) noexcept;
    uint64_t time() const { return time_ns_; }
    // The segment's own clock (its slaves' local time) against the time set_time gives: `offset_ns`
    // apart from the first set_time on, running `drift_ppm` fast (the crystals of another
    // machine). Default 0 and 0: the slaves' local time is set_time's.
    void set_clock(int64_t offset_ns, double drift_ppm) noexcept {
        clock_offset_ns_ = offset_ns;
        drift_ppm_ = drift_ppm;
    }
    double clock_rate() const noexcept { return 1.0 + drift_ppm_ * 1e-6; } // local ns per set_time ns
    // The segment's DC system time now [ns]: that of its first plugged slave with DC (the
    // reference clock the master picks); the local time if it has none.
    uint64_t dc_system_time() noexcept;
    // Drift control: a time the master writes into the reference clock's system-time register
    // (FPWR 0x0910; the FRMW that carries the reference's time to the others reads it there) pulls
    // the segment's clock towards it, by at most kMaxSteerNs per write (the simulator's model of
    // an ESC's time control loop: the whole segment follows its reference at once).
    static constexpr int64_t kMaxSteerNs = 1000;
    int64_t steered_ns() const noexcept { return steer_ns_; } // sum of the pulls so far

    // Fault injection. An unplugged slave is bypassed (frames pass it untouched); on replug it
    // comes back powered up again: INIT, no station address, SMs/FMMUs cleared.
    void unplug(std::size_t position);
    void replug(std::size_t position);
    bool plugged(std::size_t position) const { return slaves_.at(position).plugged; }
    // Drops (or corrupts: wrong header) that fraction of frames, reproducibly from `seed`.
    void set_frame_loss(double fraction, uint64_t seed = 1);
    void set_frame_corruption(double fraction, uint64_t seed = 2);
    // The line is cut after `position`: frames turn back there, later slaves see nothing
    // (-1: no break).
    void break_after(int position) { break_after_ = position; }
    int broken_after() const { return break_after_; }
    // Answers come back `us` later than they would (a slow or congested link): the in-process
    // link and the UDP server hold each frame that long. The master sees them late when that
    // is beyond its receive time-out (dropped, counted).
    void set_answer_delay_us(uint32_t us) { answer_delay_us_ = us; }
    uint32_t answer_delay_us() const noexcept { return answer_delay_us_; }
    // A power cycle with another device at `position` (a replaced terminal).
    void replace(std::size_t position, const DeviceDesc& desc);

    // Faults from another thread (faults.hpp): post() queues one (one producer thread; false if
    // the queue is full); the segment applies it before the next frame on its own thread. Faults
    // on the plant (glitch, drive-fault) go to on_plant_fault.
    bool post(const Fault& f) { return faults_.push(f); }
    // Applies a fault now (the segment's thread, or before it runs). False if it is a plant fault
    // and nobody takes it.
    bool apply(const Fault& f);
    std::function<bool(const Fault&)> on_plant_fault;
    uint64_t faults_applied = 0;
    // Called after every frame that passed the segment (terminal models, plants).
    std::function<void(Segment&)> on_frame;

    uint64_t frames = 0, frames_lost = 0, frames_corrupted = 0;

private:
    struct Slot {
        std::unique_ptr<Esc> esc;
        const DeviceDesc* desc;
        bool plugged = true;
    };
    std::vector<Slot> slaves_;
    std::vector<std::unique_ptr<DeviceDesc>> descs_;
    uint64_t time_ns_ = 0;
    uint64_t local_ns_ = 0;      // the slaves' local time (time_ns_ through the segment's clock)
    uint64_t clock_t0_ = 0;      // the first set_time (0: none yet)
    int64_t clock_offset_ns_ = 0;
    int64_t steer_ns_ = 0;
    uint64_t ref_writes_seen_ = 0; // the reference's system_time_writes already acted on
    int ref_seen_ = -1;            // the slave they were counted on
    double drift_ppm_ = 0;
    double loss_ = 0, corrupt_ = 0;
    int break_after_ = -1;
    uint32_t answer_delay_us_ = 0;
    SpscQueue<Fault> faults_{64};
    std::vector<std::unique_ptr<DeviceDesc>> replaced_;
    std::mt19937_64 loss_rng_{1}, corrupt_rng_{2};
};

} // namespace beamctl::ethercat::sim
