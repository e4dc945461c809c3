#include "daq/timed_output.hpp"

#include <algorithm>
#include <cmath>

namespace beamctl::daq {

void PcompPredictor::reset() noexcept {
    samples_ = 0;
    shadow_ = Pcomp{};
}

bool PcompPredictor::step(const PcompParams& p, bool enable, double x, uint64_t x_ns, uint64_t target_ns, uint64_t period_ns) noexcept {
    const double period = double(period_ns);
    const double lead = double(int64_t(target_ns - x_ns)) / period; // cycles (a difference: DC times exceed a double's 53 bits)
    // velocity [INP per cycle] over the window
    const unsigned want = unsigned(std::clamp<uint64_t>(kWindowNs / std::max<uint64_t>(period_ns, 1), 1, kHistory - 1));
    const unsigned back = std::min(want, samples_);
    const double velocity = back ? (x - history_[(newest_ + kHistory - back + 1) % kHistory]) / double(back) : 0;
    newest_ = (newest_ + 1) % kHistory;
    history_[newest_] = x;
    samples_ = std::min(samples_ + 1, kHistory);
    shadow_.params = p;
    shadow_.step(enable, x + lead * velocity);
    if (!shadow_.rose() && !shadow_.fell()) return false;
    edge_ns_ = target_ns - uint64_t(std::llround((1.0 - shadow_.edge_fraction()) * period));
    return true;
}

void TimedPcompOutput::reset() noexcept {
    predictor_.reset();
    size_ = 0;
}

void TimedPcompOutput::step(const PcompParams& p, bool enable, double x, uint64_t x_ns, uint64_t dc_ns, uint64_t period_ns) noexcept {
    if (predictor_.step(p, enable, x, x_ns, dc_ns + uint64_t(kHorizon) * period_ns, period_ns)) {
        if (size_ < kQueue) {
            queue_[(head_ + size_) % kQueue] = Edge{predictor_.edge_ns(), predictor_.rose()};
            ++size_;
        } else {
            ++late_; // a queue of eight edges is only full when edges come faster than one per two cycles
        }
    }
    // the terminal: this cycle's frame passes at dc + period, the next one at dc + 2 periods
    const uint64_t this_frame = dc_ns + period_ns, next_frame = dc_ns + 2 * period_ns;
    if (phase_ == Phase::Armed && armed_at_ <= this_frame) phase_ = Phase::Idle; // fired before this frame
    if (phase_ == Phase::Loaded) {
        activate_ = 3; // arms the single shot at start_
        phase_ = Phase::Armed;
        return;
    }
    while (phase_ == Phase::Idle && size_ > 0) {
        const Edge e = queue_[head_];
        head_ = (head_ + 1) % kQueue;
        --size_;
        if (e.at <= next_frame) { // armed with the next frame, it would never fire
            ++late_;
            continue;
        }
        start_ = armed_at_ = e.at;
        level_ = e.level;
        activate_ = 0;
        phase_ = Phase::Loaded;
        ++scheduled_;
    }
}

void OversampledPcompOutput::step(const PcompParams& p, bool enable, double x, uint64_t x_ns, uint64_t dc_ns, uint64_t period_ns,
                                  unsigned n) noexcept {
    // this frame passes at dc + period and plays its samples until dc + 2 periods
    const uint64_t frame = dc_ns + period_ns;
    before_ = level_;
    first_changed_ = 0;
    if (!predictor_.step(p, enable, x, x_ns, frame + period_ns, period_ns)) return;
    level_ = predictor_.rose();
    ++edges_;
    // sample k plays at frame + (k + 1) * period / n: the first at or after the edge
    n = std::max(n, 1u);
    const double into = double(int64_t(predictor_.edge_ns() - frame)) / double(period_ns) * double(n);
    first_changed_ = unsigned(std::clamp(std::ceil(into - 1.0 - 1e-9), 0.0, double(n - 1)));
}

} // namespace beamctl::daq
