// A PLC host for tests: names map to a table of doubles, some of them read-only; `static.*`
// and `global.*` names are created on first use (as the IOC does); host functions are
// registered lambdas; println output is collected.
#pragma once

#include "plc/program.hpp"

#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

namespace beamctl::plc::test {

class TableHost : public Host {
public:
    // A writable (or read-only) scalar; its address never changes.
    double& add(const std::string& name, double value = 0, bool writable = true) {
        auto& slot = table_[name];
        slot.data.assign(1, value);
        slot.writable = writable;
        return slot.data[0];
    }
    // A vector of `size` doubles.
    std::vector<double>& add_vector(const std::string& name, std::size_t size,
                                    bool writable = true) {
        auto& slot = table_[name];
        slot.data.assign(size, 0.0);
        slot.writable = writable;
        return slot.data;
    }
    double& operator[](const std::string& name) {
        auto it = table_.find(name);
        if (it == table_.end()) return add(name);
        return it->second.data[0];
    }
    bool has(const std::string& name) const { return table_.count(name) != 0; }

    using Fn = std::function<double(const double*, int)>;
    void add_function(const std::string& name, int min_args, int max_args, Fn fn) {
        functions_[name] = std::make_unique<Entry>(Entry{std::move(fn), min_args, max_args});
    }

    std::optional<Binding> resolve(std::string_view name) override {
        resolved.emplace_back(name);
        const std::string n(name);
        auto it = table_.find(n);
        if (it == table_.end()) {
            if (n.rfind("static.", 0) != 0 && n.rfind("global.", 0) != 0) return std::nullopt;
            add(n);
            it = table_.find(n);
        }
        return Binding{it->second.data.data(), it->second.writable,
                       static_cast<int>(it->second.data.size())};
    }

    std::optional<FunctionInfo> function(std::string_view name) override {
        auto it = functions_.find(std::string(name));
        if (it == functions_.end()) return std::nullopt;
        return FunctionInfo{&call, it->second.get(), it->second->min_args, it->second->max_args};
    }

    void print(std::string_view text) noexcept override {
        ++print_calls;
        if (keep_prints) printed.emplace_back(text);
    }

    bool keep_prints = true; // false: only count (print() then allocates nothing)
    long print_calls = 0;
    std::vector<std::string> printed;
    std::vector<std::string> resolved; // every resolve() call, in order

private:
    struct Slot {
        std::vector<double> data;
        bool writable = true;
    };
    struct Entry {
        Fn fn;
        int min_args, max_args;
    };
    static double call(void* ctx, const double* args, int n) noexcept {
        return static_cast<Entry*>(ctx)->fn(args, n);
    }
    std::map<std::string, Slot> table_;
    std::map<std::string, std::unique_ptr<Entry>> functions_;
};

} // namespace beamctl::plc::test
