#include "motion/encoder.hpp"

#include <algorithm>

namespace beamctl::motion {

void Encoder::update(double dt) noexcept {
    int width = std::clamp(p_.absolute && p_.abs_bits > 0 ? p_.abs_bits : p_.bits, 1, 64);
    uint64_t wmask = width >= 64 ? ~uint64_t(0) : (uint64_t(1) << width) - 1;
    uint64_t raw = raw_.get_raw() & p_.mask & wmask;
    bool first = !started_;
    if (first) {
        started_ = true;
        counts_ = int64_t(raw); // the counter as it reads at start
    } else {
        // signed difference in the counter's width: a wrap is a small step, not a jump
        uint64_t d = (raw - last_raw_) & wmask;
        bool negative = width < 64 && (d >> (width - 1) & 1);
        counts_ += negative ? int64_t(d | ~wmask) : int64_t(d);
    }
    last_raw_ = raw;
    double pos = double(counts_) * p_.numerator / p_.denominator + offset_ + (p_.absolute ? p_.abs_offset : 0);
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

double Encoder::position_at_raw(uint64_t raw) const noexcept {
    int width = std::clamp(p_.absolute && p_.abs_bits > 0 ? p_.abs_bits : p_.bits, 1, 64);
    uint64_t wmask = width >= 64 ? ~uint64_t(0) : (uint64_t(1) << width) - 1;
    uint64_t d = ((raw & p_.mask & wmask) - last_raw_) & wmask;
    bool negative = width < 64 && (d >> (width - 1) & 1);
    int64_t counts = counts_ + (negative ? int64_t(d | ~wmask) : int64_t(d));
    return double(counts) * p_.numerator / p_.denominator + offset_ + (p_.absolute ? p_.abs_offset : 0);
}

void Encoder::set_position(double pos) noexcept {
    offset_ += pos - position_;
    position_ = pos;
}

} // namespace beamctl::motion
