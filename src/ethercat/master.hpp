// The EtherCAT master: brings a segment up the way a real master does (reset, count, station
// addresses, SII, identity check, mailbox SMs, PREOP, startup SDOs, PDO layout from CoE or SII,
// process-data SMs and FMMUs, SAFEOP, OP) and exchanges process data cyclically with the
// working-counter check; CoE SDO upload/download over the mailbox.
// Self-healing (docs/ethercat.md "Missing slaves, hot connect"): by default a configured slave that
// is absent, answers with another identity or fails its configuration does not stop the bus: it is
// left out (its image region reserved from the catalog's default layout) and joins when it
// appears; a slave that is lost and returns is configured again. Every slave maps its AL status
// register into the cyclic LRW (one byte each), so each cycle tells which slaves took part and in
// which state, and a slave's data is valid (`ec<m>.s<k>.valid`) only in a cycle in which it did.
// Threading: bring_up(), the SDO calls and the diagnostics run on a non-RT thread, never while
// another thread runs the cycle; send_process_data()/receive_process_data() are the RT path:
// noexcept, no allocation.
#pragma once

#include "core/error.hpp"
#include "ethercat/device.hpp"
#include "ethercat/frame.hpp"
#include "registry/signal.hpp"
#include "ethercat/link.hpp"
#include "ethercat/outage.hpp"
#include "core/spsc_queue.hpp"
#include "ethercat/sii.hpp"

#include <atomic>
#include <memory>
#include <mutex>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace beamctl::ethercat {

class Catalog;

// A CoE SDO download done in PREOP before the PDO layout is read (ecmccfg's Cfg.EcAddSdo).
struct StartupSdo {
    uint16_t index = 0;
    uint8_t sub = 0;
    uint64_t value = 0; // written little-endian; must fit `size` bytes (signed or unsigned)
    uint8_t size = 0;   // [bytes] 1, 2, 4 or 8
};

// One configured slave: what the configuration expects at a bus position.
struct SlaveConfig {
    SlaveConfig() = default;
    SlaveConfig(int position_, std::string type_, std::vector<StartupSdo> sdos_ = {})
        : position(position_)
        , type(std::move(type_))
        , sdos(std::move(sdos_)) {}
    int position = 0;
    std::string type;             // catalog type, e.g. "EL1008"
    std::vector<StartupSdo> sdos; // in order; only for CoE devices
    unsigned oversampling = 1;    // samples per cycle of an oversampling terminal (EL3702, EL4732)
};

// An SDO transfer the slave aborted; what() names bus, position, object and the abort code.
class SdoAbort : public Error {
public:
    SdoAbort(const std::string& msg, uint32_t code)
        : Error(msg)
        , code_(code) {}
    uint32_t code() const { return code_; }

private:
    uint32_t code_;
};

// A process-image entry registered as a signal, e.g. "ec0.s3.positionActual01".
struct SignalInfo {
    std::string name;
    int slave = 0;           // bus position (-1: the master itself, e.g. ec0.masterstatus)
    uint32_t bit_offset = 0; // in the process image
    uint8_t bits = 0;
    bool output = false;
    std::string datatype;   // ETG.1020 name (UINT, DINT, BOOL, ...) or the catalog's CoE name (INT32, REAL64, ...)
    bool is_signed = false; // two's complement (from datatype, set once at registration)
    uint8_t real = 0;       // 32/64: an IEEE float (from datatype, set with is_signed)
    registry::ImageEntry entry() const { return {bit_offset, bits, is_signed, real}; }
};

struct SlaveInfo {
    int position = 0;
    uint16_t station = 0;
    std::string type;
    unsigned oversampling = 1; // SlaveConfig::oversampling: sample PDOs per channel, DC SYNC0 = cycle/n
    SiiInfo sii;
    // PDO layout in use: read over CoE (0x1C12/0x1C13 and the mappings) in PREOP for CoE
    // slaves, else the SII defaults.
    std::vector<std::pair<uint8_t, uint16_t>> pdo_assign; // {sm, pdo}
    std::vector<Pdo> rx_pdos, tx_pdos;
    bool pdo_from_coe = false;
    uint8_t al_state = 0;
    uint16_t al_status_code = 0;
    uint32_t out_offset = 0, out_bytes = 0; // byte range in the process image (outputs first)
    uint32_t in_offset = 0, in_bytes = 0;
};

enum class CycleStatus : uint8_t { Ok, WkcMismatch, FrameLost, LinkError };

// Where a configured slave stands, as the master's health pass sees it.
enum class SlaveState : uint8_t {
    Op,          // configured by the master and in OP
    Missing,     // nothing answers at its position (absent at start)
    WrongId,     // something answers at its position with another identity: left alone
    Error,       // present but its configuration or a state change failed (last_error says why)
    Lost,        // was in OP, stopped answering
    Configuring, // being configured (again) by the health pass
};
const char* slave_state_name(SlaveState s);

// ECMC's error ids for a slave (ecmcEcSlave.h, ecmcEc.h).
namespace slave_error {
constexpr uint32_t kNotOnline = 0x24012;        // ERROR_EC_SLAVE_NOT_ONLINE
constexpr uint32_t kNotOperational = 0x24011;   // ERROR_EC_SLAVE_NOT_OPERATIONAL
constexpr uint32_t kVerificationFail = 0x26026; // ERROR_EC_SLAVE_VERIFICATION_FAIL (identity)
} // namespace slave_error

// Per-slave history and state for diagnostics and PVs; written by the health pass, read as a copy.
struct SlaveHealth {
    SlaveState state = SlaveState::Op;
    uint32_t lost = 0;         // times it stopped answering (or left OP) while in the cycle
    uint32_t reconfigured = 0; // times it was configured and brought to OP after the start
    uint32_t refused = 0;      // configuration attempts that failed, or identity mismatches seen
    uint32_t error_id = 0;     // slave_error::*, 0 while in OP
};

class Master {
public:
    Master(Link& link, int bus_id, std::vector<SlaveConfig> cfg, const Catalog& catalog);

    // Brings every configured slave to OP. A slave that is absent, of another identity or fails its
    // configuration is left out with a log line naming position, expected and found (Missing,
    // WrongId, Error), unless strict: then that throws Error naming the bus, position and cause.
    // Throws if the link does not answer at all.
    void bring_up();
    // Refuse to start with a slave missing, wrong or failing (the behaviour before self-healing).
    void set_strict(bool strict) { strict_ = strict; }
    bool strict() const { return strict_; }
    // Takes every slave back to SAFEOP (outputs safe, inputs still read), after the cycle has
    // stopped (a clean shutdown). Non-RT. Throws Error naming the slave that did not get there.
    // Slaves not taking part (missing, lost) are not asked.
    void to_safe_op();
    // Counts the slaves on the segment (BRD); -1 if the link did not answer.
    int count_slaves();

    // ---- RT path ----
    // Sends the cyclic frame(s) with the current outputs.
    CycleStatus send_process_data() noexcept;
    // Receives them (waiting up to timeout_us each), copies inputs into the image, checks WKC.
    CycleStatus receive_process_data(int timeout_us = 2000) noexcept;
    // The process image: the part exchanged on the bus (outputs of all slaves, then inputs) and,
    // after it, the master's own memory (ec<m>.masterstatus, per-slave ONE/ZERO).
    uint8_t* image() { return image_.data(); }
    std::size_t image_size() const { return image_.size(); }
    std::size_t bus_bytes() const { return bus_bytes_; }
    uint32_t outputs_size() const { return outputs_bytes_; }
    // The last cycle's working counter and the error counters; any thread (relaxed atomics).
    uint16_t wkc() const { return wkc_.load(std::memory_order_relaxed); }
    // The working counter with every configured slave in OP.
    uint16_t expected_wkc() const { return expected_wkc_; }
    // The last cycle's frames came back with the working counter the slaves that took part in it
    // give (a slave absent or joining is accounted for by its status byte); ec<m>.masterstatus.
    bool cycle_ok() const { return cycle_ok_.load(std::memory_order_relaxed); }
    // Slaves answering the last cycle's broadcast read (BRD 0x0130), configured or not; -1 none.
    int responding() const { return responding_.load(std::memory_order_relaxed); }
    // Slave i's inputs and outputs took part in the last cycle, in OP, with a consistent working
    // counter (ec<m>.s<k>.valid). Any thread.
    bool slave_valid(std::size_t i) const noexcept { return valid_[i].load(std::memory_order_relaxed); }
    uint64_t frames_lost() const { return frames_lost_.load(std::memory_order_relaxed); }
    uint64_t wkc_errors() const { return wkc_errors_.load(std::memory_order_relaxed); }
    // Cyclic frames that came back after their cycle's receive time-out (dropped as too old).
    uint64_t frames_late() const { return frames_late_; }
    // AL status byte (state | 0x10 error) and presence of slave i in the last cycle whose frames
    // came back, from its status byte in the LRW (0: it did not answer).
    uint8_t slave_al_status(std::size_t i) const noexcept { return slave_al_[i].load(std::memory_order_relaxed); }
    bool slave_online(std::size_t i) const noexcept { return slave_online_[i].load(std::memory_order_relaxed); }

    // ---- while cycling (non-RT) ----
    // From now on transact() (and SII, SDO, state requests) travel as one extra datagram per
    // cycle through the RT thread's frames instead of using the link directly. Call after
    // bring_up(), before the RT thread starts.
    void start_cycling() { cycling_.store(true, std::memory_order_release); }
    // One health pass (non-RT thread, while cycling): a slave that stopped answering is reported
    // once; a slave that answers again at its position (power-cycled: INIT, no station address)
    // or left OP is configured again, start-up SDOs and DC included, and brought back to OP while
    // the others keep cycling; a slave missing since the start joins the same way when it appears,
    // once its identity checks. Returns the number of slaves brought (back) to OP.
    // Each pass also watches for bus outages (check_outage()).
    int check_and_recover();
    uint64_t recoveries() const { return recoveries_.load(); }
    // Whether a health pass has work (a slave not in OP, the responding count changed): the
    // health thread runs a pass at once instead of waiting for its period.
    bool health_due() const;
    SlaveHealth slave_health(std::size_t i) const;
    // The slave's last problem in words ("" if none yet).
    std::string slave_last_error(std::size_t i) const;
    // Changes whenever any slave's health changes (a cheap "look again" for the IOC loop).
    uint64_t health_version() const { return health_version_.load(std::memory_order_acquire); }
    SlaveState slave_state(std::size_t i) const { return slave_health(i).state; }
    // Configured slaves in OP with valid data (last cycle).
    int slaves_op() const;
    // Logs a bus outage (no frames back, a wrong working counter) when it begins, at most every
    // 5 s while it lasts with what is wrong, and when it ends with its duration (OutageMonitor).
    // `now_s`: monotonic time [s]. Returns the line logged, or "". Health thread, while cycling.
    std::string check_outage(double now_s);

    // ---- distributed clocks ----
    // Cycle time for SYNC0 of DC slaves [ns]; set before bring_up() (default 1 ms).
    void set_cycle_time_ns(uint64_t ns) { cycle_ns_ = ns; }
    // Index (in slaves()) of the reference clock: the first slave with DC, or -1.
    int dc_reference() const { return dc_ref_; }
    // The reference clock's system time as the last cycle's FRMW 0x0910 returned it [ns].
    uint64_t dc_reference_time() const { return dc_time_.load(std::memory_order_relaxed); }
    // Before bring_up(): this bus's DC follows another time base (buses[].dc_follow): each
    // cycle, when steer_dc() gave a skew, the reference clock gets a time written into its
    // system-time register (FPWR 0x0910, before the FRMW that carries its time on): the time
    // it will have as the frame passes (the last + one cycle) plus kDcSteerGain of the skew,
    // which its drift control pulls its clock towards. The rest of the time the datagram is a NOP.
    void set_dc_steering(bool on) { dc_steer_ = on; }
    static constexpr double kDcSteerGain = 0.125; // of the skew, per write (stable with 2-3 cycles of lag)
    // RT thread, between receive and send: the other time base minus this one [ns], newly measured.
    void steer_dc(int64_t skew_ns) noexcept {
        steer_skew_ns_ = skew_ns;
        steer_now_ = true;
    }

    // ---- diagnostics (non-RT) ----
    const std::vector<SignalInfo>& signals() const { return signals_; }
    const SignalInfo* find_signal(std::string_view name) const;
    // The signal bound to its place in this master's image, for RT code (axes, PLCs): `bit` >= 0
    // selects one bit (`ec0.s3.driveStatus01.3`). Unbound (image nullptr) if there is no such
    // signal. Valid after bring_up() for the master's life.
    registry::BoundSignal bind(std::string_view name, int bit = -1);
    const std::vector<SlaveInfo>& slaves() const { return slaves_; }
    int bus_id() const { return bus_; }
    // Reads the AL state of one slave (FPRD 0x0130); false if it did not answer.
    bool read_al_state(std::size_t slave_index, uint8_t& state, uint16_t& code);

    // Acyclic single-datagram transaction with retries (bring-up, diagnostics). Returns the
    // working counter, or -1 if no answer came back. `data` is sent and replaced by the reply.
    int transact(uint8_t cmd, uint32_t addr, void* data, uint16_t len, int retries = 3);
    int transact(uint8_t cmd, uint16_t adp, uint16_t ado, void* data, uint16_t len, int retries = 3) {
        return transact(cmd, uint32_t(adp) | uint32_t(ado) << 16, data, len, retries);
    }

    // ---- CoE SDO (non-RT, after bring_up() reached PREOP) ----
    // Reads object index:sub of the configured slave at `position` (expedited or normal
    // transfer). Throws SdoAbort if the slave aborts, Error on timeouts and protocol errors; both
    // name the bus, position and object ("ec0 position 8: SDO upload 0x8010:01 aborted: ...").
    std::vector<uint8_t> sdo_upload(int position, uint16_t index, uint8_t sub);
    // Writes `len` bytes (little-endian value) to index:sub. Throws as sdo_upload.
    void sdo_download(int position, uint16_t index, uint8_t sub, const void* data, std::size_t len);
    // How long an SDO waits for its reply.
    void set_sdo_timeout_ms(int ms) { sdo_timeout_ms_ = ms; }

    // Signal access helpers on the image (non-RT convenience; the RT side uses offsets).
    uint64_t get(const SignalInfo& s) const;
    void set(const SignalInfo& s, uint64_t v);

private:
    struct CyclicFrame {
        FrameBuilder frame;
        struct Part {
            uint32_t data_offset; // in the frame
            uint32_t image_offset;
            uint32_t len;
        };
        std::vector<Part> parts;
    };

    void read_sii(SlaveInfo& s);
    void read_pdo_layout(SlaveInfo& s);
    SlaveInfo& mailbox_slave(int position, const std::string& ctx);
    // One SDO request/response over the mailbox: `coe` is the CoE data (header + SDO) of the
    // request; returns the CoE data of the matching reply. Throws SdoAbort / Error with `ctx`.
    std::vector<uint8_t> sdo_exchange(SlaveInfo& s, const uint8_t* coe, std::size_t len,
                                      const std::string& ctx);
    bool mailbox_in_full(const SlaveInfo& s, const std::string& ctx);
    // Reads the slave->master mailbox; false if it was empty.
    bool read_mailbox(const SlaveInfo& s, std::vector<uint8_t>& buf, const std::string& ctx);
    void request_state(uint8_t state, const char* name);
    void request_state(const std::vector<std::size_t>& which, uint8_t state, const char* name);
    // As request_state, but a slave that does not get there is returned with the error (in the
    // order of `which`) instead of throwing; the others carry on.
    std::vector<std::pair<std::size_t, std::string>> request_state_each(const std::vector<std::size_t>& which,
                                                                        uint8_t state, const char* name);
    void check_identity(const SlaveInfo& s) const;
    std::string identity_error(const SlaveInfo& s) const; // "" if it is the configured device
    void sii_read4(const SlaveInfo& s, uint32_t addr, std::vector<uint16_t>& words);
    // Vendor, product, revision from SII words 0x08-0x0D into s.sii (nothing written to the slave).
    void read_identity(SlaveInfo& s);
    // The layout a slave absent at start gets reserved: the catalog device's SII defaults.
    void reserve_default_layout(SlaveInfo& s) const;
    void apply_oversampling(SlaveInfo& s) const; // the sample PDOs of SlaveInfo::oversampling
    // Brings slave i (present at its station address) from whatever state to OP: INIT, identity,
    // SMs, PREOP, start-up SDOs, PDO layout (must match the reserved one), FMMUs, DC, SAFEOP, OP.
    // `full_sii`: read the whole SII (a slave never configured); else only its identity.
    void configure_slave(std::size_t i, bool full_sii);
    // Finds slave i at its position: true if something answers there and now has its station
    // address (a fresh slave without one gets it).
    bool claim_position(std::size_t i);
    void set_health(std::size_t i, SlaveState st, uint32_t error_id, const std::string& error);
    void configure_dc_slave(std::size_t i);
    // DC registers of slave i given the reference's latched receive time (nullptr: it is its own
    // reference) and the master's time at the latch [ns since 2000].
    void configure_dc_at(std::size_t i, const uint32_t* t_ref, uint64_t master_ns);
    struct DcPending {
        std::size_t slave;
        uint32_t t_ref;
        uint64_t master_ns;
    };
    std::vector<DcPending> dc_pending_; // bring-up: one latch for all DC slaves
    void configure_mailbox(const SlaveInfo& s);
    void apply_startup_sdos(std::size_t i);
    void configure_process_data(std::size_t i);
    void configure_dc(const std::vector<std::size_t>& which);
    int transact_via_cycle(uint8_t cmd, uint32_t addr, void* data, uint16_t len, int retries);
    void layout_process_image();
    void build_cyclic_frames();
    std::string slave_name(const SlaveInfo& s) const;

    Link& link_;
    int bus_;
    std::vector<SlaveConfig> cfg_;
    const Catalog& catalog_;
    std::vector<SlaveInfo> slaves_;
    std::vector<SignalInfo> signals_;
    std::vector<uint8_t> image_;
    uint32_t outputs_bytes_ = 0;
    uint32_t bus_bytes_ = 0;            // image bytes exchanged on the bus (LRW)
    uint32_t masterstatus_offset_ = 0;  // byte offset of ec<m>.masterstatus in the image
    std::vector<CyclicFrame> cyclic_;
    int count_frame_ = -1;       // frame holding the BRD 0x0130 (responding slaves)
    uint32_t count_offset_ = 0;  // its data offset in that frame
    uint32_t status_bytes_ = 0;  // image offset of the slaves' AL status bytes (one per slave)
    uint32_t valid_offset_ = 0;  // image offset of the per-slave words ONE, ZERO, valid (12 bytes each)
    std::unique_ptr<std::atomic<uint8_t>[]> slave_al_, slave_online_, valid_; // written by the RT thread
    std::unique_ptr<std::atomic<uint8_t>[]> admit_; // health thread: the master configured it (trust its data in OP)
    std::vector<uint16_t> contrib_; // working counter slave i adds to the cycle when it takes part
    // RT: the status bytes and admissions of the last walk over the slaves, and the working
    // counter range they give (most cycles change nothing: no walk).
    std::vector<uint8_t> last_stat_;
    uint32_t wkc_lo_ = 0, wkc_hi_ = 0, admit_seen_ = ~0u;
    int last_consistent_ = -1;
    std::atomic<uint32_t> admit_gen_{0}; // health thread: bumped on every admission change
    void set_admitted(std::size_t i, bool yes);
    std::atomic<int> responding_{-1};
    std::atomic<bool> cycle_ok_{false};
    bool strict_ = false;
    mutable std::mutex health_mu_;   // guards health_
    std::vector<SlaveHealth> health_;
    std::vector<std::string> last_error_;
    std::atomic<uint64_t> health_version_{0};
    std::vector<double> retry_at_;   // health thread: next try for a slave in Error/WrongId [s, steady]
    std::vector<double> backoff_;    // its current back-off [s]
    int last_responding_ = -1;       // health thread: responding() at the last pass
    bool dc_configured_ = false;

    // Acyclic datagrams while cycling: one in flight, in its own frame after the cyclic ones.
    static constexpr std::size_t kMaxAcyclic = 512;
    struct AcyclicRequest {
        uint8_t cmd = 0;
        uint32_t addr = 0;
        uint16_t len = 0;
        uint8_t data[kMaxAcyclic];
    };
    struct AcyclicReply {
        int wkc = -1;
        uint8_t data[kMaxAcyclic];
    };
    std::atomic<bool> cycling_{false};
    SpscQueue<AcyclicRequest> acyc_req_{2};
    SpscQueue<AcyclicReply> acyc_rep_{2};
    FrameBuilder acyc_frame_;
    AcyclicRequest acyc_cur_;
    bool acyc_in_flight_ = false;
    OutageMonitor outage_;      // health thread
    std::atomic<uint64_t> recoveries_{0};
    uint64_t cycle_ns_ = 1'000'000;
    uint8_t seq_ = 0;          // cycle sequence (mod 16) carried in the cyclic datagram index
    uint64_t frames_late_ = 0;
    int dc_ref_ = -1;               // reference clock slave index
    int dc_frame_ = -1;             // frame holding the FRMW 0x0910
    uint32_t dc_offset_ = 0;        // its data offset in that frame
    std::atomic<uint64_t> dc_time_{0};
    bool dc_steer_ = false;    // set_dc_steering
    int steer_frame_ = -1;     // frame holding the FPWR 0x0910 to the reference (-1: none)
    uint32_t steer_offset_ = 0; // its data offset in that frame
    int64_t steer_skew_ns_ = 0; // RT thread
    bool steer_now_ = false;    // RT thread: a skew to act on in the next send
    uint16_t expected_wkc_ = 0;
    // Written by the RT thread only, read by the health thread.
    std::atomic<uint16_t> wkc_{0};
    std::atomic<uint64_t> frames_lost_{0}, wkc_errors_{0};
    std::atomic<bool> send_ok_{true}, frames_back_{true}; // of the last cycle
    uint8_t next_idx_ = 0x80; // acyclic indices 0x80..0xFF; cyclic 0..0x7F
    std::map<int, uint8_t> mbx_counter_; // position -> last mailbox counter sent (1..7)
    int sdo_timeout_ms_ = 1000;
    std::array<uint8_t, kMaxFrame> rx_{};
};

} // namespace beamctl::ethercat
