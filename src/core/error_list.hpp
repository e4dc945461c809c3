// Every error of one pass over an input (a configuration file, a .db file, an IOC and the files
// it names), in the order found: record an error and go on with a default, then throw once, at
// the end, a MultiError listing them all (its first line is the first error). Configuration-time
// code; an ErrorList is used by one thread.
#pragma once

#include "core/error.hpp"

#include <cstddef>
#include <string>
#include <string_view>
#include <unordered_set>
#include <vector>

namespace beamctl {

// Several errors in one exception: what() is one error per line, in order.
class MultiError : public Error {
public:
    explicit MultiError(std::vector<std::string> errors);
    const std::vector<std::string>& errors() const { return errors_; }

private:
    std::vector<std::string> errors_;
};

class ErrorList {
public:
    // An error that says where itself ("file:line:col: what" or "file: what"). An exact repeat
    // of an error already in the list is dropped.
    void add(std::string message);
    // "at: what".
    void add(const SourceLoc& at, const std::string& what);
    // The error an Error carries, or each error of a MultiError.
    void add(const Error& e);
    void append(const ErrorList& more);

    bool empty() const { return errors_.empty(); }
    std::size_t size() const { return errors_.size(); }
    const std::vector<std::string>& messages() const { return errors_; }

    // Throws a MultiError with every error, if there is one.
    void throw_if_any() const;

    // Runs f(); an Error it throws is recorded, with `context` (if any) in front of its text.
    // Returns whether f() finished without one.
    template <typename F> bool capture(F&& f, std::string_view context = {}) {
        try {
            f();
            return true;
        } catch (const MultiError& e) {
            for (const auto& m : e.errors()) add(with_context(context, m));
        } catch (const Error& e) {
            add(with_context(context, e.what()));
        }
        return false;
    }

private:
    static std::string with_context(std::string_view context, const std::string& m);
    std::vector<std::string> errors_;
    std::unordered_set<std::string> seen_; // errors_, for dropping repeats

};

} // namespace beamctl
