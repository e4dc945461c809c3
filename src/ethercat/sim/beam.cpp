#include "ethercat/sim/beam.hpp"

#include "ethercat/sim/plant.hpp"

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

void Beam::update(Segment& seg) noexcept {
    double dx = 0, dy = 0;
    for (const BeamLever& l : levers) {
        const double u = l.stage ? l.stage->position() : double(l.output.get_signed(seg)) * l.volts_per_digit;
        dx += l.x * u;
        dy += l.y * u;
    }
    dx_ = dx, dy_ = dy;
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
