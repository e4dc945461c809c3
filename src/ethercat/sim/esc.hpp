// Simulated EtherCAT slave controller (ESC): 64 KiB of register and process RAM, the EtherCAT
// datagram semantics of one slave (addressing, working counter, FMMU logical mapping with bit
// granularity), the SII EEPROM interface, sync managers (mailbox SMs with their full/empty
// handshake), the AL state machine with its checks and, for CoE devices, the slave firmware's
// mailbox handling with an SDO server. The simulator's segment calls process() for every datagram
// that passes this slave, in order, and run_firmware() once after each frame.
// Threading: a segment and its ESCs belong to one thread (the master's, for in-process links).
#pragma once

#include "ethercat/device.hpp"
#include "ethercat/frame.hpp"
#include "ethercat/sim/coe_server.hpp"

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

namespace beamctl::ethercat::sim {

// Register addresses (ethercat.md §2).
namespace reg {
constexpr uint16_t kType = 0x0000, kFmmuCount = 0x0004, kSmCount = 0x0005, kRamSize = 0x0006,
                   kFeatures = 0x0008, kStationAddress = 0x0010, kAlias = 0x0012,
                   kDlControl = 0x0100, kDlStatus = 0x0110, kAlControl = 0x0120,
                   kAlStatus = 0x0130, kAlStatusCode = 0x0134, kWdDivider = 0x0400,
                   kWdProcessData = 0x0420, kSiiConfig = 0x0500, kSiiControl = 0x0502,
                   kSiiAddress = 0x0504, kSiiData = 0x0508, kFmmu = 0x0600, kSm = 0x0800,
                   kDcRecvTime = 0x0900, kDcSystemTime = 0x0910, kDcRecvTimeEpu = 0x0918,
                   kDcOffset = 0x0920, kDcDelay = 0x0928, kDcDiff = 0x092C,
                   kDcActivation = 0x0981, kDcSync0Start = 0x0990, kDcSync0Cycle = 0x09A0;
} // namespace reg

enum AlState : uint8_t { kInit = 1, kPreop = 2, kBoot = 3, kSafeop = 4, kOp = 8 };
enum AlStatusCode : uint16_t {
    kAlNoError = 0x0000, kAlInvalidTransition = 0x0011, kAlUnknownState = 0x0012,
    kAlInvalidMailbox = 0x0016, kAlSmWatchdog = 0x001B, kAlInvalidOutputs = 0x001D,
    kAlInvalidInputs = 0x001E,
};

class Esc {
public:
    Esc(const DeviceDesc& desc, std::vector<uint16_t> sii);
    ~Esc();

    // Applies datagram d as this slave would and updates its working counter. `position` is
    // this slave's index in the segment (for logging only).
    void process(Datagram& d) noexcept;
    // What the slave's microcontroller does between frames: serves a mailbox request waiting in
    // the master->slave mailbox once the slave->master mailbox is free. Allocates only while
    // serving a request (never when idle).
    void run_firmware() noexcept;

    // The slave's view of time (ns since 2000-01-01), advanced by the segment each frame.
    void set_local_time(uint64_t ns) noexcept { local_time_ns_ = ns; }
    // Propagation delay from the master to this slave's port 0 [ns] (position x per-hop delay):
    // what the receive-time latch (0x0900) adds to the ideal common clock.
    void set_hop_delay(uint64_t ns) noexcept { hop_delay_ns_ = ns; }
    // Local system time at this instant (local clock + offset) [ns since 2000-01-01].
    uint64_t system_time() const noexcept { return local_time_ns_ + le64(&mem_[reg::kDcOffset]); }

    uint8_t al_state() const { return mem_[reg::kAlStatus] & 0x0F; }
    bool al_error() const { return mem_[reg::kAlStatus] & 0x10; }
    uint16_t al_status_code() const { return le16(&mem_[reg::kAlStatusCode]); }
    uint16_t station_address() const { return le16(&mem_[reg::kStationAddress]); }
    const DeviceDesc& desc() const { return desc_; }

    // Process RAM seen by the terminal behaviour: the buffer of sync manager `sm` (its
    // configured start address, or the device default when not configured).
    uint8_t* sm_buffer(uint8_t sm);
    uint16_t sm_length(uint8_t sm) const;
    bool outputs_valid() const { return al_state() == kOp; }
    uint8_t* memory() { return mem_.data(); }
    // The CoE object dictionary (nullptr if the device has no CoE).
    CoeServer* coe() { return coe_.get(); }
    // Fault injection: refuse every change to `state` with AL status code `code` (0: lift it).
    void refuse_state(uint8_t state, uint16_t code) noexcept { refuse_state_ = state, refuse_code_ = code; }
    // Bytes of process data SM `sm` must have for SAFEOP: from the current CoE PDO assignment,
    // or the device's default assignment without CoE.
    uint32_t expected_sm_bytes(uint8_t sm) const;
    // Samples per channel of an oversampling terminal, taken from the SM lengths the master
    // configured when it asked for SAFEOP (1 for every other device).
    unsigned oversampling() const noexcept { return oversampling_; }

    // Counters of what the slave saw (for tests and diagnostics).
    uint64_t frames_seen = 0;
    // Times written into its system-time register 0x0910 by an FPWR (for it alone: not the FRMW
    // that carries the reference's time), and the last written time's difference to this slave's
    // own system time [ns] (what its drift control acts on: 0x092C).
    uint64_t system_time_writes = 0;
    int64_t system_time_diff_ns = 0;
    uint64_t output_writes = 0; // logical writes that reached an output FMMU
    uint64_t watchdog_trips = 0; // OP -> SAFEOP by the SM watchdog
    uint64_t mailbox_requests = 0, mailbox_rejected_writes = 0;

private:
    uint8_t refuse_state_ = 0;
    uint16_t refuse_code_ = 0;
    // False (no access, no working counter) if the range touches a mailbox buffer that the
    // master may not access now (writing a full or reading an empty mailbox).
    bool read_phys(uint16_t ado, uint8_t* data, uint16_t len) noexcept;
    bool write_phys(uint16_t ado, const uint8_t* data, uint16_t len) noexcept;
    uint16_t read_write(uint16_t ado, uint8_t* data, uint16_t len, uint8_t* tmp) noexcept; // WKC
    void serve_mailbox(uint8_t sm_out, uint8_t sm_in);
    bool logical(Datagram& d, bool read, bool write, uint16_t& wkc) noexcept;
    void al_control_written() noexcept;
    void sii_command() noexcept;
    bool check_mailbox_sms() const noexcept;
    uint16_t check_process_sms() noexcept; // 0 or the AL status code (sets oversampling_)
    uint16_t check_process_sms(const std::vector<uint32_t>* os_bytes) const noexcept;
    void set_al(uint8_t state, uint16_t code) noexcept;
    void check_watchdog() noexcept;

    // Per-frame state first, next to each other (the 64 KiB memory image comes last).
    uint64_t local_time_ns_ = 0;
    uint64_t hop_delay_ns_ = 0;
    uint64_t last_output_ns_ = 0; // local time of the last process-data write (SM watchdog)
    DeviceDesc desc_;
    std::vector<uint16_t> sii_;
    std::unique_ptr<CoeServer> coe_;
    int mbx_out_ = -1, mbx_in_ = -1; // SM indices of the mailboxes (-1: none)
    uint8_t last_counter_ = 0;       // counter of the last request served (repeat detection)
    uint8_t reply_counter_ = 0;
    unsigned oversampling_ = 1;
    // Oversampling without CoE: os_sm_bytes_[k-1][sm] = SM bytes for factor k (k = 1..max).
    std::vector<std::vector<uint32_t>> os_sm_bytes_;
    std::array<uint8_t, 65536> mem_{};
};

} // namespace beamctl::ethercat::sim
