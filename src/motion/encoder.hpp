// An axis encoder (ECMC `encoder:`): the raw counter entry turned into a position.
//   incremental  the counter (`bits` wide) wraps; wraps are tracked into a 64-bit count
//   absolute     `absBits` valid bits after `mask`; `absOffset` [units] added; wraps tracked too
//   scaling      position [units] = counts * numerator / denominator (+ offset set by homing)
//   correction   ECMC `lookuptable:`: once homed (absolute encoders always), scale * table(x) is
//                subtracted, x the position (modulo `range` into [0, range) when range > 0)
// Velocity is the filtered difference of positions (moving average over `filter_size` cycles).
// Threading: RT thread; all calls noexcept, no allocation.
#pragma once

#include "core/lookup_table.hpp"
#include "registry/signal.hpp"

#include <array>
#include <cstdint>
#include <memory>

namespace beamctl::motion {

struct EncoderParams {
    double numerator = 1, denominator = 1; // [units] per `denominator` counts
    bool absolute = false;
    int bits = 16;            // width of the raw counter [bits] (wrap at 2^bits)
    int abs_bits = 0;         // absolute: valid bits (0 = bits)
    uint64_t mask = ~uint64_t(0); // applied to the raw value first
    double abs_offset = 0;    // absolute: added to the position [units]
    int filter_size = 10;     // velocity moving average [cycles], 1..kMaxFilter
    std::shared_ptr<const LookupTable> correction; // lookuptable (null: none)
    double correction_range = 0, correction_scale = 1; // [units]; factor
    bool ref_at_home = false; // homing.refAtHome: a non-primary encoder set with the primary's homing
    static constexpr int kMaxFilter = 100;
};

class Encoder {
public:
    Encoder() = default;
    Encoder(const EncoderParams& p, registry::BoundSignal raw) : p_(p), raw_(raw) {}
    // Reads the counter; `dt` [s] is the cycle period. The first call only initialises.
    void update(double dt) noexcept;
    double position() const noexcept { return position_; } // [units]
    double velocity() const noexcept { return velocity_; } // [units/s]
    int64_t counts() const noexcept { return counts_; }
    uint64_t last_raw() const noexcept { return last_raw_; } // the counter as last read (masked)
    bool valid() const noexcept { return started_; }
    // The position [units] at which the counter read `raw` (a latched value): the difference to
    // the last reading in the counter's width, so wraps in between are fine.
    double position_at_raw(uint64_t raw) const noexcept;
    // Homing / set position: from now on position() reads `pos` here.
    void set_position(double pos) noexcept;
    bool homed() const noexcept { return homed_ || p_.absolute; }
    // position() - counts * scale [units]: the offset between the axis frame and the counter's
    // own frame (homing, set position, absOffset); CSP setpoints are sent in the counter's frame.
    double frame_offset() const noexcept { return offset_ + (p_.absolute ? p_.abs_offset : 0); }
    void set_homed(bool h) noexcept { homed_ = h; }
    const EncoderParams& params() const noexcept { return p_; }

private:
    uint64_t width_mask() const noexcept;         // the counter's bits (absBits for absolute)
    int64_t counts_at(uint64_t raw) const noexcept; // counts where the counter reads `raw`
    EncoderParams p_;
    registry::BoundSignal raw_;
    bool started_ = false, homed_ = false;
    uint64_t last_raw_ = 0;
    int64_t counts_ = 0;
    double offset_ = 0; // [units], from set_position
    double position_ = 0, velocity_ = 0;
    std::array<double, EncoderParams::kMaxFilter> vbuf_{};
    int vhead_ = 0, vcount_ = 0;
    double vsum_ = 0;
};

} // namespace beamctl::motion
