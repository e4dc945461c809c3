// EPICS Access Security Configuration File (ACF): parser and rights evaluator, following the
// semantics of EPICS base asLib (UAG, HAG, ASG, RULE with levels, NONE/READ/WRITE, TRAPWRITE).
// Threading: an AccessSecurity is immutable once built; const members may be called concurrently
// from any thread, and copies share the parsed configuration.
#pragma once

#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::ca {

namespace detail {
struct AccessConfig;
}

// Rights of a client on one field; write implies read (kAccessWrite is never returned alone).
enum AccessBits : unsigned { kAccessNone = 0, kAccessRead = 1, kAccessWrite = 2 };

class AccessSecurity {
public:
    // No ACF: access security disabled, everyone may read and write everything.
    AccessSecurity();

    // Parses ACF text; `filename` only names the source in messages. Throws beamctl::Error
    // "file:line:col: what" on any syntax error, undefined UAG/HAG, duplicate UAG/HAG/ASG, or
    // unsupported feature (INP<A-L>, CALC, macros).
    static AccessSecurity parse(std::string_view text, const std::string& filename);
    // Reads and parses a file; throws beamctl::Error if it cannot be read or parsed.
    static AccessSecurity load_file(const std::string& path);

    // False when no ACF was loaded (default-constructed).
    bool enabled() const;

    // Rights (AccessBits) of a CA client on a field of access-security level `field_level`
    // (0 = ASL0, e.g. VAL; 1 = ASL1) in record group `asg` (the record's ASG field; "" or a group
    // not in the file means DEFAULT). `user` is the CA CLIENT_NAME (compared exactly), `host` the
    // CA HOST_NAME (compared case-insensitively), `peer_ip` the client's IPv4 address as
    // "a.b.c.d" (matched against HAG entries written as dotted IPv4 addresses; may be "").
    // The result is the highest right of the applicable rules; RPC (a pvAccess right) gives none.
    unsigned rights(std::string_view asg, int field_level, std::string_view user,
                    std::string_view host, std::string_view peer_ip) const;

    // True when `asg` is "" or names a group of the loaded file (DEFAULT always exists);
    // false when disabled.
    bool has_group(std::string_view asg) const;
    // Names of all groups in byte order, including DEFAULT; empty when disabled.
    std::vector<std::string> groups() const;

private:
    explicit AccessSecurity(std::shared_ptr<const detail::AccessConfig> config);
    std::shared_ptr<const detail::AccessConfig> config_; // null when disabled
};

} // namespace beamctl::ca
