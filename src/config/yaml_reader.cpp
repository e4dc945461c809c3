#include "config/yaml_reader.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

namespace beamctl::config {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::optional<int64_t> parse_int(std::string_view s) {
    bool neg = false;
    if (!s.empty() && (s[0] == '+' || s[0] == '-')) {
        neg = s[0] == '-';
        s.remove_prefix(1);
    }
    int base = 10;
    if (s.size() > 2 && s[0] == '0' && (s[1] == 'x' || s[1] == 'X')) {
        base = 16;
        s.remove_prefix(2);
    }
    if (s.empty()) return std::nullopt;
    uint64_t v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v, base);
    if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
    const uint64_t max = uint64_t(std::numeric_limits<int64_t>::max());
    if (!neg && v > max) return std::nullopt;
    if (neg && v > max + 1) return std::nullopt;
    return neg ? int64_t(0 - v) : int64_t(v);
}

std::optional<uint64_t> parse_uint(std::string_view s) {
    if (!s.empty() && s[0] == '+') s.remove_prefix(1);
    int base = 10;
    if (s.size() > 2 && s[0] == '0' && (s[1] == 'x' || s[1] == 'X')) {
        base = 16;
        s.remove_prefix(2);
    }
    if (s.empty()) return std::nullopt;
    uint64_t v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v, base);
    if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
    return v;
}

std::optional<double> parse_double(std::string_view s) {
    if (auto i = parse_int(s)) return double(*i);
    if (!s.empty() && s[0] == '+') s.remove_prefix(1);
    // [-]digits[.digits][e[+-]digits] or [-].digits...; no inf, nan or hex floats
    std::size_t i = 0, digits = 0;
    if (i < s.size() && s[i] == '-') ++i;
    while (i < s.size() && std::isdigit(static_cast<unsigned char>(s[i]))) ++i, ++digits;
    if (i < s.size() && s[i] == '.') {
        ++i;
        while (i < s.size() && std::isdigit(static_cast<unsigned char>(s[i]))) ++i, ++digits;
    }
    if (digits == 0) return std::nullopt;
    if (i < s.size() && (s[i] == 'e' || s[i] == 'E')) {
        ++i;
        if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
        std::size_t exp_digits = 0;
        while (i < s.size() && std::isdigit(static_cast<unsigned char>(s[i]))) ++i, ++exp_digits;
        if (exp_digits == 0) return std::nullopt;
    }
    if (i != s.size()) return std::nullopt;
    double v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || end != s.data() + s.size() || !std::isfinite(v)) return std::nullopt;
    return v;
}

std::optional<bool> parse_bool(std::string_view s) {
    static constexpr std::string_view yes[] = {"true", "True", "TRUE", "yes", "Yes",
                                               "YES",  "on",   "On",   "ON",  "1"};
    static constexpr std::string_view no[] = {"false", "False", "FALSE", "no",  "No",
                                              "NO",    "off",   "Off",   "OFF", "0"};
    for (auto y : yes)
        if (s == y) return true;
    for (auto n : no)
        if (s == n) return false;
    return std::nullopt;
}

// "a, b or c"
std::string or_list(std::initializer_list<std::string_view> items) {
    SB sb;
    std::size_t i = 0;
    for (auto it : items) {
        if (i > 0) sb << (i + 1 == items.size() ? " or " : ", ");
        sb << it;
        ++i;
    }
    return sb;
}

std::string best_match(std::string_view word, const std::vector<std::string>& candidates) {
    auto m = close_matches(word, candidates, 1);
    return m.empty() ? std::string() : m.front();
}

} // namespace

std::optional<int64_t> parse_integer(std::string_view s) {
    return parse_int(s);
}
std::optional<double> parse_number(std::string_view s) {
    return parse_double(s);
}
std::optional<bool> parse_boolean(std::string_view s) {
    return parse_bool(s);
}

// ---- Range ------------------------------------------------------------------------------------

std::string Range::str() const {
    if (lo_open && hi == kInf) return SB() << "> " << lo;
    if (hi == kInf) return SB() << ">= " << lo;
    if (lo == -kInf) return SB() << "<= " << hi;
    if (lo_open) return SB() << "> " << lo << " and <= " << hi;
    return SB() << "from " << lo << " to " << hi;
}
Range above(double lo) {
    return {lo, kInf, true};
}
Range at_least(double lo) {
    return {lo, kInf, false};
}
Range at_most(double hi) {
    return {-kInf, hi, false};
}
Range between(double lo, double hi) {
    return {lo, hi, false};
}

// ---- close matches ----------------------------------------------------------------------------

std::size_t edit_distance(std::string_view a, std::string_view b) {
    const auto lower = [](char c) { return std::tolower(static_cast<unsigned char>(c)); };
    const std::size_t n = a.size(), m = b.size();
    std::vector<std::size_t> d((n + 1) * (m + 1));
    const auto at = [&](std::size_t i, std::size_t j) -> std::size_t& { return d[i * (m + 1) + j]; };
    for (std::size_t i = 0; i <= n; ++i) at(i, 0) = i;
    for (std::size_t j = 0; j <= m; ++j) at(0, j) = j;
    for (std::size_t i = 1; i <= n; ++i)
        for (std::size_t j = 1; j <= m; ++j) {
            const std::size_t cost = lower(a[i - 1]) == lower(b[j - 1]) ? 0 : 1;
            at(i, j) = std::min({at(i - 1, j) + 1, at(i, j - 1) + 1, at(i - 1, j - 1) + cost});
            if (i > 1 && j > 1 && lower(a[i - 1]) == lower(b[j - 2]) &&
                lower(a[i - 2]) == lower(b[j - 1]))
                at(i, j) = std::min(at(i, j), at(i - 2, j - 2) + 1);
        }
    return at(n, m);
}

std::vector<std::string> close_matches(std::string_view word,
                                       const std::vector<std::string>& candidates,
                                       std::size_t max) {
    // A typo: up to 1 edit in a short word, 2 from 5 characters, 3 from 10; never all of it.
    const std::size_t limit = word.size() >= 10 ? 3 : word.size() >= 5 ? 2 : 1;
    std::vector<std::pair<std::size_t, std::string>> found;
    for (const auto& c : candidates) {
        const std::size_t d = edit_distance(word, c);
        if (d <= limit && d < word.size() && d < c.size() && c != word) found.emplace_back(d, c);
    }
    std::stable_sort(found.begin(), found.end(),
                     [](const auto& x, const auto& y) { return x.first < y.first; });
    std::vector<std::string> out;
    for (auto& f : found) {
        if (out.size() == max) break;
        if (std::find(out.begin(), out.end(), f.second) == out.end()) out.push_back(f.second);
    }
    return out;
}

const char* describe(const YAML::Node& n) {
    if (n.IsMap()) return "a mapping";
    if (n.IsSequence()) return "a list";
    if (!n.IsDefined() || n.IsNull()) return "nothing";
    return "a single value";
}

// ---- YamlReader -------------------------------------------------------------------------------

YamlReader::YamlReader(std::string file, std::string text, std::string name)
    : file_(std::move(file))
    , text_(std::move(text))
    , name_(std::move(name)) {
    line_starts_.push_back(0);
    for (std::size_t i = 0; i < text_.size(); ++i)
        if (text_[i] == '\n') line_starts_.push_back(i + 1);
    std::vector<YAML::Node> docs;
    try {
        docs = YAML::LoadAll(text_);
    } catch (const YAML::Exception& e) {
        SourceLoc at = top();
        if (e.mark.line >= 0 && e.mark.column >= 0) at = {file_, e.mark.line + 1, e.mark.column + 1};
        error(at, SB() << "YAML syntax error: " << e.msg);
        return;
    }
    if (docs.size() > 1) {
        error(loc(docs[1]), "only one YAML document is expected (a second one starts here)");
        return;
    }
    doc_ = docs.empty() ? YAML::Node(YAML::NodeType::Null) : docs[0];
    parsed_ = true;
}

YamlReader YamlReader::load(const std::string& path, std::string name) {
    std::ifstream f(path, std::ios::binary);
    if (!f) {
        const int err = errno;
        YamlReader r(path, "", std::move(name));
        r.parsed_ = false;
        r.errors_.clear();
        r.errors_.emplace_back(SourceLoc{path, 0, 0},
                               SB() << path << ": cannot open: " << std::strerror(err));
        return r;
    }
    std::ostringstream ss;
    ss << f.rdbuf();
    return YamlReader(path, ss.str(), std::move(name));
}

YamlNode YamlReader::root() {
    if (!parsed_) return YamlNode(this, YAML::Node(), "", top(), false);
    return YamlNode(this, doc_, "", top(), true);
}

SourceLoc YamlReader::loc(const YAML::Node& n) const {
    const YAML::Mark m = n.Mark();
    if (m.line < 0 || m.column < 0) return top();
    SourceLoc l{file_, m.line + 1, m.column + 1};
    if (n.IsScalar() && n.Tag() == "!" && std::size_t(m.line) < line_starts_.size()) {
        const std::size_t at = line_starts_[std::size_t(m.line)] + std::size_t(m.column);
        if (at < text_.size() && (text_[at] == '\'' || text_[at] == '"')) ++l.col;
    }
    return l;
}

void YamlReader::error(const SourceLoc& at, const std::string& what) {
    std::string text = SB() << at.str() << ": " << what;
    if (!seen_.insert(text).second) return;
    errors_.emplace_back(at, std::move(text));
}

void YamlReader::warn(const SourceLoc& at, const std::string& what) {
    std::string text = SB() << at.str() << ": " << what;
    if (std::find(warnings_.begin(), warnings_.end(), text) == warnings_.end())
        warnings_.push_back(std::move(text));
}

void YamlReader::take_errors(ErrorList& into) {
    std::stable_sort(errors_.begin(), errors_.end(), [](const auto& a, const auto& b) {
        return std::pair(a.first.line, a.first.col) < std::pair(b.first.line, b.first.col);
    });
    for (auto& e : errors_) into.add(std::move(e.second));
    errors_.clear();
    seen_.clear();
}

ErrorList YamlReader::take_errors() {
    ErrorList l;
    take_errors(l);
    return l;
}

void YamlReader::throw_if_errors() {
    take_errors().throw_if_any();
}

std::optional<std::string> YamlReader::expand(const std::string& raw, const SourceLoc& at,
                                              const std::string& path) {
    if (!expander_) return raw;
    return expander_(raw, at, path);
}

// ---- YamlNode ---------------------------------------------------------------------------------

std::string YamlNode::name() const {
    return path_.empty() ? (rd_ ? rd_->name() : std::string("the file")) : path_;
}

std::string YamlNode::sub(std::string_view key) const {
    return path_.empty() ? std::string(key) : std::string(SB() << path_ << "." << key);
}

SourceLoc YamlNode::loc() const {
    if (!present_ || node_.IsNull() || !rd_) return key_at_;
    return rd_->loc(node_);
}

SourceLoc YamlNode::text_loc(bool* literal) const {
    if (literal) *literal = false;
    SourceLoc l = loc();
    if (!is_scalar() || !rd_) return l;
    const YAML::Mark m = node_.Mark();
    const auto& starts = rd_->line_starts_;
    const std::string& text = rd_->text_;
    if (m.line < 0 || m.column < 0 || std::size_t(m.line) >= starts.size()) return l;
    const std::size_t at = starts[std::size_t(m.line)] + std::size_t(m.column);
    if (at >= text.size() || (text[at] != '|' && text[at] != '>')) return l;
    for (std::size_t line = std::size_t(m.line) + 1; line < starts.size(); ++line) { // first non-blank
        std::size_t b = starts[line], e = text.find('\n', b);
        if (e == std::string::npos) e = text.size();
        std::size_t i = text.find_first_not_of(" \t\r", b);
        if (i == std::string::npos || i >= e) continue;
        if (literal) *literal = text[at] == '|';
        // The text's line 1 is the line after the indicator (leading blank lines are kept), at
        // the block's indentation (its first non-blank line's).
        return SourceLoc{l.file, m.line + 2, int(i - b) + 1};
    }
    return l;
}

void YamlNode::error(const std::string& what) const {
    if (!rd_) return;
    if (path_.empty())
        rd_->error(loc(), what);
    else
        rd_->error(loc(), SB() << path_ << ": " << what);
}

void YamlNode::error_here(const std::string& what) const {
    if (rd_) rd_->error(loc(), what);
}

void YamlNode::warn(const std::string& what) const {
    if (rd_) rd_->warn(loc(), what);
}

bool YamlNode::keys(std::initializer_list<std::string_view> allowed,
                    std::initializer_list<KnownKey> known) const {
    if (!present_ || node_.IsNull()) return present_;
    if (!node_.IsMap()) {
        rd_->error(loc(), SB() << name() << " should be a mapping (key: value lines), got "
                               << describe(node_));
        return false;
    }
    std::vector<std::pair<std::string, SourceLoc>> seen;
    for (auto it = node_.begin(); it != node_.end(); ++it) {
        const YAML::Node k = it->first;
        if (!k.IsScalar()) {
            rd_->error(rd_->loc(k), SB() << "keys in " << name() << " should be names, got "
                                         << describe(k));
            continue;
        }
        const std::string key = k.Scalar();
        const SourceLoc at = rd_->loc(k);
        const auto same = std::find_if(seen.begin(), seen.end(),
                                       [&](const auto& s) { return s.first == key; });
        if (same != seen.end()) {
            rd_->error(at, SB() << "duplicate key '" << key << "' in " << name()
                                << " (also at line " << same->second.line << ")");
            continue;
        }
        seen.emplace_back(key, at);
        if (std::find(allowed.begin(), allowed.end(), key) != allowed.end()) continue;
        const auto kn = std::find_if(known.begin(), known.end(),
                                     [&](const KnownKey& i) { return i.key == key; });
        if (kn != known.end()) {
            if (kn->error && rd_->unknown_keys_ignored_)
                rd_->warn(at, SB() << "unknown key '" << key << "' in " << name() << ": "
                                   << kn->hint << " (ignored)");
            else if (kn->error)
                rd_->error(at, SB() << "unknown key '" << key << "' in " << name() << ": "
                                    << kn->hint);
            else
                rd_->warn(at, SB() << "'" << sub(key) << "' " << kn->hint);
            continue;
        }
        SB msg;
        msg << "unknown key '" << key << "' in " << name();
        if (std::string best = best_match(key, std::vector<std::string>(allowed.begin(), allowed.end()));
            !best.empty()) {
            msg << " (did you mean '" << best << "'?)";
        } else {
            msg << " (expected one of: ";
            std::size_t i = 0;
            for (auto a : allowed) msg << (i++ ? ", " : "") << a;
            msg << ")";
        }
        if (rd_->unknown_keys_ignored_)
            rd_->warn(at, SB() << std::string(msg) << ": ignored, as ECMC does");
        else
            rd_->error(at, msg);
    }
    return true;
}

YamlNode YamlNode::operator[](std::string_view key) const {
    // An absent key is placed where this value's key is (the section that lacks it).
    if (!present_ || !node_.IsMap()) return YamlNode(rd_, YAML::Node(), sub(key), key_at_, false);
    YamlNode found(rd_, YAML::Node(), sub(key), key_at_, false);
    for (auto it = node_.begin(); it != node_.end(); ++it)
        if (it->first.IsScalar() && it->first.Scalar() == key)
            found = YamlNode(rd_, it->second, sub(key), rd_->loc(it->first), true);
    return found;
}

YamlNode YamlNode::required(std::string_view key, std::string_view hint) const {
    YamlNode n = (*this)[key];
    // Nothing more to say about a section that is missing or not a mapping itself, nor when a
    // misspelt key is there: its "did you mean" says it.
    if (n.present_ || !present_ || !(node_.IsMap() || node_.IsNull())) return n;
    std::string misspelt;
    if (node_.IsMap())
        for (auto it = node_.begin(); it != node_.end(); ++it)
            if (it->first.IsScalar() &&
                !close_matches(it->first.Scalar(), {std::string(key)}, 1).empty())
                misspelt = it->first.Scalar();
    // Where unknown keys are only warnings, the missing key is the error, naming the misspelt one.
    if (!misspelt.empty() && !rd_->unknown_keys_ignored_) return n;
    rd_->error(key_at_, SB() << name() << ": missing required key '" << key << "'" << hint
                             << (misspelt.empty() ? std::string() : " ('" + misspelt + "' is not it)"));
    return n;
}

std::vector<std::pair<std::string, YamlNode>> YamlNode::entries() const {
    std::vector<std::pair<std::string, YamlNode>> out;
    if (!present_ || node_.IsNull()) return out;
    if (!node_.IsMap()) {
        rd_->error(loc(), SB() << name() << " should be a mapping (key: value lines), got "
                               << describe(node_));
        return out;
    }
    for (auto it = node_.begin(); it != node_.end(); ++it) {
        if (!it->first.IsScalar()) {
            rd_->error(rd_->loc(it->first), SB() << "keys in " << name()
                                                 << " should be names, got "
                                                 << describe(it->first));
            continue;
        }
        const std::string k = it->first.Scalar();
        out.emplace_back(k, YamlNode(rd_, it->second, sub(k), rd_->loc(it->first), true));
    }
    return out;
}

std::vector<YamlNode> YamlNode::list() const {
    std::vector<YamlNode> out;
    if (!present_ || node_.IsNull()) return out;
    if (!node_.IsSequence()) {
        rd_->error(loc(), SB() << name() << " should be a list, got " << describe(node_));
        return out;
    }
    for (std::size_t i = 0; i < node_.size(); ++i) {
        const YAML::Node item = node_[i];
        out.push_back(YamlNode(rd_, item, SB() << path_ << "[" << i << "]", rd_->loc(item), true));
    }
    return out;
}

std::optional<std::string> YamlNode::scalar(std::string_view what) const {
    if (!present_) return std::nullopt;
    if (node_.IsNull()) {
        rd_->error(key_at_, SB() << name() << " has no value (should be " << what << ")");
        return std::nullopt;
    }
    if (!node_.IsScalar()) {
        rd_->error(loc(), SB() << name() << " should be " << what << ", got " << describe(node_));
        return std::nullopt;
    }
    return rd_->expand(node_.Scalar(), loc(), path_);
}

std::optional<std::string> YamlNode::string() const {
    return scalar("a text");
}

std::optional<double> YamlNode::number(Range r) const {
    auto s = scalar("a number");
    if (!s) return std::nullopt;
    const auto v = parse_double(*s);
    if (!v) {
        rd_->error(loc(), SB() << name() << " should be a number, got '" << *s << "'");
        return std::nullopt;
    }
    if (!r.ok(*v)) {
        rd_->error(loc(), SB() << name() << " should be " << r.str() << ", got " << *s);
        return std::nullopt;
    }
    return v;
}

std::optional<int64_t> YamlNode::integer(Range r) const {
    auto s = scalar("an integer");
    if (!s) return std::nullopt;
    const auto v = parse_int(*s);
    if (!v) {
        rd_->error(loc(), SB() << name() << " should be an integer, got '" << *s << "'");
        return std::nullopt;
    }
    if (!r.ok(double(*v))) {
        rd_->error(loc(), SB() << name() << " should be " << r.str() << ", got " << *s);
        return std::nullopt;
    }
    return v;
}

std::optional<uint64_t> YamlNode::unsigned_integer(uint64_t max) const {
    auto s = scalar("an unsigned integer");
    if (!s) return std::nullopt;
    const auto v = parse_uint(*s);
    if (!v) {
        rd_->error(loc(), SB() << name() << " should be an unsigned integer, got '" << *s << "'");
        return std::nullopt;
    }
    if (*v > max) {
        rd_->error(loc(), SB() << name() << " should be from 0 to " << max << ", got " << *s);
        return std::nullopt;
    }
    return v;
}

std::optional<bool> YamlNode::boolean() const {
    auto s = scalar("true or false");
    if (!s) return std::nullopt;
    const auto v = parse_bool(*s);
    if (!v) rd_->error(loc(), SB() << name() << " should be true or false, got '" << *s << "'");
    return v;
}

std::optional<std::string> YamlNode::one_of(std::initializer_list<std::string_view> choices) const {
    auto s = scalar(or_list(choices));
    if (!s) return std::nullopt;
    if (std::find(choices.begin(), choices.end(), *s) != choices.end()) return s;
    SB msg;
    msg << name() << " should be " << or_list(choices) << ", got '" << *s << "'";
    if (std::string best = best_match(*s, std::vector<std::string>(choices.begin(), choices.end()));
        !best.empty())
        msg << " (did you mean '" << best << "'?)";
    rd_->error(loc(), msg);
    return std::nullopt;
}

std::vector<std::pair<std::string, std::string>> YamlNode::string_pairs() const {
    std::vector<std::pair<std::string, std::string>> out;
    for (auto& [k, v] : entries())
        if (auto s = v.string()) out.emplace_back(k, std::move(*s));
    return out;
}

std::map<std::string, std::string> YamlNode::string_map() const {
    std::map<std::string, std::string> out;
    for (auto& [k, v] : string_pairs()) out[k] = v;
    return out;
}

} // namespace beamctl::config
