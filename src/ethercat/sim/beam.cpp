#include "ethercat/sim/beam.hpp"

#include "ethercat/sim/plant.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace beamctl::ethercat::sim {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kTwoPi = 6.283185307179586;

// The fraction of a normal distribution (mean mu, deviation s) inside [a, b].
double inside(double a, double b, double mu, double s) noexcept {
    if (!(b > a)) return 0;
    const double k = 1 / (s * std::sqrt(2.0));
    const double lo = a == -kInf ? 1.0 : std::erfc((a - mu) * k) / 2; // P(X > a)
    const double hi = b == kInf ? 0.0 : std::erfc((b - mu) * k) / 2;  // P(X > b)
    return std::max(0.0, lo - hi);
}

} // namespace

BeamExposure exposure(const BeamTally& a, const BeamTally& b) noexcept {
    BeamExposure e;
    e.seconds = b.w - a.w;
    e.sigma_x = b.sigma_x, e.sigma_y = b.sigma_y, e.flux = b.flux;
    e.left = b.left, e.right = b.right, e.bottom = b.bottom, e.top = b.top;
    if (!(e.seconds > 0)) { // no step between: the latest position, no spread
        e.x = b.x, e.y = b.y, e.transmission = b.transmission;
        return e;
    }
    e.x = (b.sx - a.sx) / e.seconds;
    e.y = (b.sy - a.sy) / e.seconds;
    e.var_x = std::max(0.0, (b.sxx - a.sxx) / e.seconds - e.x * e.x);
    e.var_y = std::max(0.0, (b.syy - a.syy) / e.seconds - e.y * e.y);
    e.transmission = std::clamp((b.st - a.st) / e.seconds, 0.0, 1.0);
    return e;
}

BeamTally Beam::tally() noexcept {
    published_.update();
    return published_.read_buffer();
}

void Beam::update(Segment& seg, double t, double dt) noexcept {
    double dx = 0, dy = 0;
    for (const BeamLever& l : levers) {
        const double u = l.stage ? l.stage->position() : double(l.output.get_signed(seg)) * l.volts_per_digit;
        dx += l.x * u;
        dy += l.y * u;
    }
    dx_ = dx, dy_ = dy;
    // the step's contribution to the tally, at its end (steps are one cycle: ~1 ms)
    const double x = this->x(t), y = this->y(t);
    sum_.t = t;
    if (dt > 0) {
        sum_.w += dt;
        sum_.sx += x * dt, sum_.sxx += x * x * dt;
        sum_.sy += y * dt, sum_.syy += y * y * dt;
        sum_.st += diode_at(0, x, y) / p_.flux * dt;
    }
    sum_.x = x, sum_.y = y, sum_.transmission = diode_at(0, x, y) / p_.flux;
    sum_.sigma_x = p_.sigma_x, sum_.sigma_y = p_.sigma_y, sum_.flux = p_.flux;
    sum_.left = left ? left->position() : -kInf, sum_.right = right ? right->position() : kInf;
    sum_.bottom = bottom ? bottom->position() : -kInf, sum_.top = top ? top->position() : kInf;
    published_.write_buffer() = sum_;
    published_.publish();
}

double Beam::x(double t) const noexcept {
    return p_.x0 + dx_ + p_.drift_x * t + p_.vibration_x * std::sin(kTwoPi * p_.vibration_hz * t);
}

double Beam::y(double t) const noexcept {
    return p_.y0 + dy_ + p_.drift_y * t + p_.vibration_y * std::sin(kTwoPi * p_.vibration_hz * t);
}

double Beam::transmission(double t) const noexcept { return diode_at(0, x(t), y(t)) / p_.flux; }

double Beam::diode(int which, double t) const noexcept { return diode_at(which, x(t), y(t)); }

double Beam::diode_at(int which, double cx, double cy) const noexcept {
    // the aperture, cut to the diode's quadrant
    double x0 = left ? left->position() : -kInf, x1 = right ? right->position() : kInf;
    double y0 = bottom ? bottom->position() : -kInf, y1 = top ? top->position() : kInf;
    const bool plus_x = which == 2 || which == 3, plus_y = which == 1 || which == 2;
    if (which >= 1 && which <= 4) {
        if (plus_x) x0 = std::max(x0, 0.0);
        else x1 = std::min(x1, 0.0);
        if (plus_y) y0 = std::max(y0, 0.0);
        else y1 = std::min(y1, 0.0);
    }
    return p_.flux * inside(x0, x1, cx, p_.sigma_x) * inside(y0, y1, cy, p_.sigma_y);
}

} // namespace beamctl::ethercat::sim
