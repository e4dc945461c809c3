#include "core/error_list.hpp"


namespace beamctl {
namespace {

std::string join_lines(const std::vector<std::string>& errors) {
    std::string s;
    for (const auto& e : errors) {
        if (!s.empty()) s += '\n';
        s += e;
    }
    return s;
}

} // namespace

MultiError::MultiError(std::vector<std::string> errors)
    : Error(join_lines(errors))
    , errors_(std::move(errors)) {}

void ErrorList::add(std::string message) {
    if (!seen_.insert(message).second) return;
    errors_.push_back(std::move(message));
}

void ErrorList::add(const SourceLoc& at, const std::string& what) {
    add(SB() << at.str() << ": " << what);
}

void ErrorList::add(const Error& e) {
    if (const auto* m = dynamic_cast<const MultiError*>(&e)) {
        for (const auto& s : m->errors()) add(s);
        return;
    }
    add(std::string(e.what()));
}

void ErrorList::append(const ErrorList& more) {
    for (const auto& s : more.errors_) add(s);
}

void ErrorList::throw_if_any() const {
    if (!errors_.empty()) throw MultiError(errors_);
}

std::string ErrorList::with_context(std::string_view context, const std::string& m) {
    if (context.empty()) return m;
    return SB() << context << ": " << m;
}

} // namespace beamctl
