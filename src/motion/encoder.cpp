#include "motion/encoder.hpp"

#include <cmath>

#include <algorithm>

namespace beamctl::motion {

void Encoder::update(double dt) noexcept {
    uint64_t raw = raw_.get_raw() & p_.mask & width_mask();
    bool first = !started_;
    counts_ = first ? int64_t(raw) : counts_at(raw); // at start: the counter as it reads
    started_ = true;
    last_raw_ = raw;
    double pos = double(counts_) * p_.numerator / p_.denominator + frame_offset();
    if (p_.correction && homed()) {
        double x = pos;
        if (p_.correction_range > 0) {
            x = std::fmod(pos, p_.correction_range);
            if (pos < 0) x += p_.correction_range;
        }
        pos -= p_.correction_scale * p_.correction->value(x);
    }
    if (!first && dt > 0) {
        int n = std::clamp(p_.filter_size, 1, EncoderParams::kMaxFilter);
        double v = (pos - position_) / dt;
        if (vcount_ >= n) vsum_ -= vbuf_[std::size_t(vhead_)];
        else ++vcount_;
        vbuf_[std::size_t(vhead_)] = v;
        vsum_ += v;
        vhead_ = (vhead_ + 1) % n;
        velocity_ = vsum_ / vcount_;
    }
    position_ = pos;
}

uint64_t Encoder::width_mask() const noexcept {
    int width = std::clamp(p_.absolute && p_.abs_bits > 0 ? p_.abs_bits : p_.bits, 1, 64);
    return width >= 64 ? ~uint64_t(0) : (uint64_t(1) << width) - 1;
}

int64_t Encoder::counts_at(uint64_t raw) const noexcept {
    // signed difference to the last reading in the counter's width: a wrap is a small step
    uint64_t wmask = width_mask();
    uint64_t d = ((raw & p_.mask & wmask) - last_raw_) & wmask;
    bool negative = wmask != ~uint64_t(0) && (d & ((wmask >> 1) + 1)) != 0; // top bit set
    return counts_ + (negative ? int64_t(d | ~wmask) : int64_t(d));
}

double Encoder::position_at_raw(uint64_t raw) const noexcept {
    return double(counts_at(raw)) * p_.numerator / p_.denominator + frame_offset();
}

void Encoder::set_position(double pos) noexcept {
    offset_ += pos - position_;
    position_ = pos;
}

} // namespace beamctl::motion
