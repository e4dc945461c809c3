// ECMC's m2m ("machine to machine"): 120 values shared by the PLCs of the IOCs on one computer,
// plus each IOC's running and EtherCAT-OK state, by its master index (ECMC: -15..15; negative
// for IOCs without a master). ECMC keeps them in SysV shared memory ("ecmc_shm") behind a
// semaphore; beamctl in a POSIX shared-memory object (/dev/shm/<name>) of lock-free 64-bit
// cells, so the cycle never blocks on another process.
// Threading: the constructor and destructor on a non-RT thread; the rest on the RT thread (any
// number of processes at once: every cell is an atomic).
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

namespace beamctl::plc {

class M2m {
public:
    static constexpr int kElements = 120;   // ECMC_SHM_ELEMENTS
    static constexpr int kMaxMasters = 16;  // ECMC_SHM_MAX_MASTERS: master ids -15..15
    static constexpr uint32_t kIndexOutOfRange = 0x20059; // ERROR_SHM_INDEX_OUT_OF_RANGE
    static constexpr uint32_t kNotValid = 0x2005A;        // ERROR_SHM_NULL

    // Opens (creating if needed) the shared object `name` (a plain name: "beamctl_m2m") for the
    // IOC whose master index is `master`. Throws Error naming it when it cannot.
    M2m(const std::string& name, int master);
    ~M2m(); // this IOC: not running any more
    M2m(const M2m&) = delete;
    M2m& operator=(const M2m&) = delete;

    const std::string& name() const { return name_; }
    int master() const { return master_; }

    // RT
    uint32_t write(double index, double value) noexcept;
    double read(double index, uint32_t& error) const noexcept; // 0 on error
    // This IOC's state, every cycle: running, EtherCAT OK.
    void set_state(bool ec_ok) noexcept;
    // Another IOC's (master index -15..15): 1/0, or -1 for an index out of range. ec_ok is 0
    // for an IOC without a master (negative index), as ECMC.
    double ioc_running(double master) const noexcept;
    double ioc_ec_ok(double master) const noexcept;

private:
    struct Shared {
        std::atomic<uint64_t> values[kElements];     // doubles, bit for bit
        std::atomic<uint8_t> running[2 * kMaxMasters]; // by master + kMaxMasters
        std::atomic<uint8_t> ec_ok[2 * kMaxMasters];
    };
    static_assert(std::atomic<uint64_t>::is_always_lock_free, "m2m cells must be lock-free across processes");
    int slot(double master) const noexcept; // -1 if out of range
    std::string name_;
    int master_;
    Shared* s_ = nullptr;
};

} // namespace beamctl::plc
