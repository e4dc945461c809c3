// The one reader of every YAML configuration file (ARCHITECTURE.md §3): the IOC file, ECMC axis
// and encoder files, the simulator's plant file, the device catalog, the rcp-sim model.
//
// A YamlReader parses one file; its YamlNodes are values with their key path ("axes[2].file")
// and place. Typed getters (string, number in a Range, integer, unsigned, bool, one of a set,
// list, mapping) return nullopt for an absent key, and for a bad value after recording the error;
// the caller goes on with its default, so one pass finds every error of the file. keys() makes
// every other key an error with a close-match hint, required() a missing key. Each error reads
// "file:line:col: <key path> <what>", e.g.
//   ioc.yaml:7:14: engine.rate_hz should be from 1 to 20000, got 0
//   axis.yaml:31:5: unknown key 'velocty' in trajectory.axis (did you mean 'velocity'?)
// At the end, throw_if_errors() throws one MultiError with every error, sorted by position.
//
// Scalars follow YAML 1.1 as PyYAML reads them (ecmccfg's reader): integers decimal or 0x-hex
// with a sign, finite decimal numbers, booleans true/false, yes/no, on/off (any of the three
// capitalisations) and 1/0. Quotes do not change a scalar's type ("5" is a number).
//
// Configuration-time code: a reader and its nodes are used by one thread.
#pragma once

#include "core/error.hpp"
#include "core/error_list.hpp"

#include <yaml-cpp/yaml.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_set>
#include <utility>
#include <vector>

namespace beamctl::config {

// Allowed numbers, for checks and messages ("should be > 0", "should be from 1 to 255").
struct Range {
    double lo = -std::numeric_limits<double>::infinity();
    double hi = std::numeric_limits<double>::infinity();
    bool lo_open = false; // lo itself is not allowed

    bool ok(double v) const { return (lo_open ? v > lo : v >= lo) && v <= hi; }
    std::string str() const;
};
Range above(double lo);                 // > lo
Range at_least(double lo);              // >= lo
Range at_most(double hi);               // <= hi
Range between(double lo, double hi);    // lo..hi, both included

// A key outside the schema that the reader knows. A warning reads "'<path>' <hint>" (hint: "is
// ignored by ecmccfg (use X)"); an error "unknown key '<key>' in <mapping>: <hint>".
struct KnownKey {
    std::string_view key;
    std::string_view hint;
    bool error = false;
};

// Edit distance (Damerau: a swap of two neighbours counts 1), ASCII case ignored.
std::size_t edit_distance(std::string_view a, std::string_view b);
// The candidates close to `word` (a typo of it), closest first, at most `max`.
std::vector<std::string> close_matches(std::string_view word,
                                       const std::vector<std::string>& candidates,
                                       std::size_t max = 3);

class YamlReader;

// A value of the file with its key path and place. A key that is not in the file gives a node
// that is not present(); every getter returns nullopt (or nothing) for it, without an error.
class YamlNode {
public:
    YamlNode() = default;

    bool present() const { return present_; }
    explicit operator bool() const { return present_; }
    bool is_null() const { return present_ && node_.IsNull(); } // `key:` without a value
    bool is_map() const { return present_ && node_.IsMap(); }
    bool is_list() const { return present_ && node_.IsSequence(); }
    bool is_scalar() const { return present_ && node_.IsScalar(); }
    const std::string& path() const { return path_; } // "" for the file itself
    // The path, or the reader's name of the file for the root ("the IOC file").
    std::string name() const;
    // The value's place; for a null value, its key's; for an absent key, its mapping's.
    SourceLoc loc() const;
    std::string where() const { return loc().str(); }
    // Where its key is; for a list item, the item; for an absent key, its mapping's key.
    SourceLoc key_loc() const { return key_at_; }
    const YAML::Node& yaml() const { return node_; }
    // Where a scalar's text begins: loc(), or for a `|`/`>` block the first character of its first
    // line; *literal is set for a `|` block (its lines are the file's lines, at that column).
    SourceLoc text_loc(bool* literal = nullptr) const;
    // The raw text of a scalar, before expansion ("" for anything else).
    std::string raw() const { return is_scalar() ? node_.Scalar() : std::string(); }

    // ---- mappings
    // Declares the keys this mapping may have: any other key, a duplicate key and a value that
    // is not a mapping are errors (a null value is an empty mapping). Returns false when the
    // value is not a mapping.
    bool keys(std::initializer_list<std::string_view> allowed,
              std::initializer_list<KnownKey> known = {}) const;
    // The value of `key` (the last one if given twice); not present() if absent.
    YamlNode operator[](std::string_view key) const;
    bool has(std::string_view key) const { return (*this)[key].present(); }
    // As operator[]; an absent key is an error "<name>: missing required key 'key'<hint>" at
    // this value's key. Nothing is said about a value that is not a mapping (keys() does), nor
    // when a key close to `key` is there (its unknown-key error says "did you mean").
    YamlNode required(std::string_view key, std::string_view hint = {}) const;
    // Keys and values in file order; an error if present and not a mapping.
    std::vector<std::pair<std::string, YamlNode>> entries() const;

    // ---- lists
    // The items ("<path>[i]"); an error if present and not a list.
    std::vector<YamlNode> list() const;

    // ---- scalars: nullopt if absent, or after recording why the value is bad
    // The text of a scalar after expansion; `what` says what it should be in errors ("a number").
    std::optional<std::string> scalar(std::string_view what) const;
    std::optional<std::string> string() const;
    std::optional<double> number(Range r = {}) const;
    std::optional<int64_t> integer(Range r = {}) const;
    std::optional<uint64_t> unsigned_integer(uint64_t max = UINT64_MAX) const;
    std::optional<bool> boolean() const;
    // One of `choices` (exactly); otherwise an error listing them, with a hint when close.
    std::optional<std::string> one_of(std::initializer_list<std::string_view> choices) const;
    // A mapping of scalars (macro definitions, record fields), in file order.
    std::vector<std::pair<std::string, std::string>> string_pairs() const;
    std::map<std::string, std::string> string_map() const;

    // Records "<loc>: <path>: <what>" ("<loc>: <what>" for the root).
    void error(const std::string& what) const;
    // Records "<loc>: <what>" (the caller names the key).
    void error_here(const std::string& what) const;
    void warn(const std::string& what) const;
    YamlReader& reader() const { return *rd_; }

private:
    friend class YamlReader;
    YamlNode(YamlReader* rd, YAML::Node node, std::string path, SourceLoc key_at, bool present)
        : rd_(rd)
        , node_(std::move(node))
        , path_(std::move(path))
        , key_at_(std::move(key_at))
        , present_(present) {}
    std::string sub(std::string_view key) const;

    YamlReader* rd_ = nullptr;
    YAML::Node node_;
    std::string path_;
    SourceLoc key_at_; // where the key is; the mapping's place for an absent key
    bool present_ = false;
};

class YamlReader {
public:
    // Parses `text` (one YAML document); a syntax error, or a second document, is an error and
    // leaves root() absent. `name` is how messages call the file itself ("the IOC file").
    YamlReader(std::string file, std::string text, std::string name = "the file");
    // Reads `path`; a file that cannot be read is an error "path: cannot open: why".
    static YamlReader load(const std::string& path, std::string name = "the file");
    YamlReader(const YamlReader&) = delete;
    YamlReader& operator=(const YamlReader&) = delete;
    YamlReader(YamlReader&&) = default;

    const std::string& file() const { return file_; }
    const std::string& name() const { return name_; }
    // The document: absent after a read or syntax error, null for an empty file.
    YamlNode root();
    // The place of `n` in the file; a quoted scalar starts after its quote.
    SourceLoc loc(const YAML::Node& n) const;
    SourceLoc top() const { return {file_, 1, 1}; }

    // Each scalar's text passes through this before conversion (e.g. macro expansion); it
    // returns nullopt after recording an error. Default: the text as written.
    using Expander = std::function<std::optional<std::string>(
        const std::string& raw, const SourceLoc& at, const std::string& path)>;
    void set_expander(Expander e) { expander_ = std::move(e); }

    // Keys outside a mapping's schema (unknown ones, and KnownKeys marked error) are warnings
    // "..., ignored" instead of errors: for ECMC's files, whose loader drops them (ecmccfg's
    // cerberus validator runs with purge_unknown), so that every file ECMC accepts loads.
    void set_unknown_keys_ignored(bool on) { unknown_keys_ignored_ = on; }

    void error(const SourceLoc& at, const std::string& what);
    void warn(const SourceLoc& at, const std::string& what);
    bool ok() const { return errors_.empty(); }
    std::size_t error_count() const { return errors_.size(); }
    // The errors so far, sorted by position, moved out of the reader.
    ErrorList take_errors();
    void take_errors(ErrorList& into);
    // Throws a MultiError with every error (sorted by position) if there is one.
    void throw_if_errors();
    std::vector<std::string> take_warnings() { return std::move(warnings_); }

private:
    friend class YamlNode;
    std::optional<std::string> expand(const std::string& raw, const SourceLoc& at,
                                      const std::string& path);

    std::string file_, text_, name_;
    std::vector<std::size_t> line_starts_;
    YAML::Node doc_;
    bool parsed_ = false;
    Expander expander_;
    bool unknown_keys_ignored_ = false;
    std::vector<std::pair<SourceLoc, std::string>> errors_;
    std::unordered_set<std::string> seen_; // the texts of errors_, for dropping repeats
    std::vector<std::string> warnings_;
};

// Scalar syntax of the reader (see the top): nullopt when `s` is not one.
std::optional<int64_t> parse_integer(std::string_view s);
std::optional<double> parse_number(std::string_view s); // finite
std::optional<bool> parse_boolean(std::string_view s);

// Describes a node's kind for messages: "a mapping", "a list", "nothing", "a single value".
const char* describe(const YAML::Node& n);

} // namespace beamctl::config
