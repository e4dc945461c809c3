// The names automation's expressions (compound motors' forward/inverse, state machines' guards,
// collision zones) may use, bound to the owner's storage: a plc::Host over a list of
// (name, double*) pairs, compiled once, at start-up. Not RT: the owner runs the programs on the
// IOC loop.
#pragma once

#include "plc/program.hpp"

#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace beamctl::automation {

class ExpressionNames final : public plc::Host {
public:
    // `what` names the owner in "unknown name" errors ("compound motor group 'energy'").
    explicit ExpressionNames(std::string what = "the expressions") : what_(std::move(what)) {}
    void bind(const std::string& name, double* at, bool writable) { names_.push_back({name, plc::Binding{at, writable, 1}}); }
    std::optional<plc::Binding> resolve(std::string_view n) override {
        for (const auto& [name, b] : names_)
            if (name == n) return b;
        return std::nullopt;
    }
    // "<what> knows a, b, c" (the first 40 readable names).
    std::string why_unknown(std::string_view) override {
        std::string s = what_ + " knows";
        int shown = 0;
        for (const auto& [name, b] : names_)
            if (!b.writable && shown++ < 40) s += (shown > 1 ? ", " : " ") + name;
        return s;
    }
    void assigned(std::string_view n) override { assigned_.emplace_back(n); }
    const std::vector<std::string>& assigned_names() const { return assigned_; }

private:
    std::string what_;
    std::vector<std::pair<std::string, plc::Binding>> names_;
    std::vector<std::string> assigned_;
};

} // namespace beamctl::automation
