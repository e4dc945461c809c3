// The EtherCAT master: brings a segment up the way a real master does (reset, count, station
// addresses, SII, identity check, mailbox SMs, PDO layout from SII, process-data SMs and FMMUs,
// INIT->PREOP->SAFEOP->OP) and exchanges process data cyclically with the working-counter check.
// Threading: bring_up() and the diagnostics run on a non-RT thread before the cycle starts;
// send_process_data()/receive_process_data() are the RT path: noexcept, no allocation.
#pragma once

#include "ethercat/device.hpp"
#include "ethercat/frame.hpp"
#include "ethercat/link.hpp"
#include "ethercat/sii.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace beamctl::ethercat {

class Catalog;

// One configured slave: what the configuration expects at a bus position.
struct SlaveConfig {
    int position = 0;
    std::string type; // catalog type, e.g. "EL1008"
};

// A process-image entry registered as a signal, e.g. "ec0.s3.positionActual01".
struct SignalInfo {
    std::string name;
    int slave = 0;
    uint32_t bit_offset = 0; // in the process image
    uint8_t bits = 0;
    bool output = false;
    std::string datatype;
};

struct SlaveInfo {
    int position = 0;
    uint16_t station = 0;
    std::string type;
    SiiInfo sii;
    uint8_t al_state = 0;
    uint16_t al_status_code = 0;
    uint32_t out_offset = 0, out_bytes = 0; // byte range in the process image (outputs first)
    uint32_t in_offset = 0, in_bytes = 0;
};

enum class CycleStatus : uint8_t { Ok, WkcMismatch, FrameLost, LinkError };

class Master {
public:
    Master(Link& link, int bus_id, std::vector<SlaveConfig> cfg, const Catalog& catalog);

    // Brings every configured slave to OP. Throws Error naming the bus, position and cause.
    void bring_up();
    // Counts the slaves on the segment (BRD); -1 if the link did not answer.
    int count_slaves();

    // ---- RT path ----
    // Sends the cyclic frame(s) with the current outputs.
    CycleStatus send_process_data() noexcept;
    // Receives them (waiting up to timeout_us each), copies inputs into the image, checks WKC.
    CycleStatus receive_process_data(int timeout_us = 2000) noexcept;
    uint8_t* image() { return image_.data(); }
    std::size_t image_size() const { return image_.size(); }
    uint32_t outputs_size() const { return outputs_bytes_; }
    uint16_t wkc() const { return wkc_; }
    uint16_t expected_wkc() const { return expected_wkc_; }
    uint64_t frames_lost() const { return frames_lost_; }
    uint64_t wkc_errors() const { return wkc_errors_; }

    // ---- diagnostics (non-RT) ----
    const std::vector<SignalInfo>& signals() const { return signals_; }
    const SignalInfo* find_signal(std::string_view name) const;
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
            uint16_t expected_wkc;
        };
        std::vector<Part> parts;
        uint8_t idx = 0;
    };

    void read_sii(SlaveInfo& s);
    void request_state(uint8_t state, const char* name);
    void layout_process_image();
    void configure_sms_and_fmmus();
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
    std::vector<CyclicFrame> cyclic_;
    uint16_t wkc_ = 0, expected_wkc_ = 0;
    uint64_t frames_lost_ = 0, wkc_errors_ = 0;
    uint8_t next_idx_ = 0x80; // acyclic indices 0x80..0xFF; cyclic 0..0x7F
    std::array<uint8_t, kMaxFrame> rx_{};
};

} // namespace beamctl::ethercat
