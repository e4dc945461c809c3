#include "ca/access_security.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <sstream>
#include <unordered_set>

namespace beamctl::ca {

namespace detail {

struct StringHash {
    using is_transparent = void;
    std::size_t operator()(std::string_view s) const { return std::hash<std::string_view>{}(s); }
};
using StringSet = std::unordered_set<std::string, StringHash, std::equal_to<>>;

// Access right written in a RULE. RPC is a pvAccess right (EPICS PR #942); it grants CA nothing.
enum class Right { none, read, write, rpc };

struct AccessConfig {
    struct Uag {
        std::string name;
        StringSet users; // compared exactly
    };
    struct Hag {
        std::string name;
        StringSet hosts_lower;             // lower-cased host names (and addresses as written)
        std::unordered_set<uint32_t> ipv4; // entries that are dotted IPv4 addresses
    };
    struct Rule {
        int level = 0; // applies to fields with level <= this
        Right right = Right::none;
        bool trap_write = false;
        std::vector<std::size_t> uags; // indices into AccessConfig::uags; empty = any user
        std::vector<std::size_t> hags; // indices into AccessConfig::hags; empty = any host
    };
    struct Group {
        std::vector<Rule> rules;
    };

    std::vector<Uag> uags;
    std::vector<Hag> hags;
    std::map<std::string, Group, std::less<>> groups; // always holds DEFAULT
};

} // namespace detail

namespace {

using detail::AccessConfig;
using detail::Right;

constexpr std::string_view kDefaultGroup = "DEFAULT";

unsigned ca_bits(Right r) {
    switch (r) {
    case Right::read:
        return kAccessRead;
    case Right::write:
        return kAccessRead | kAccessWrite;
    case Right::none:
    case Right::rpc:
        return kAccessNone;
    }
    return kAccessNone;
}

char ascii_lower(char c) {
    return (c >= 'A' && c <= 'Z') ? char(c - 'A' + 'a') : c;
}

std::string to_lower(std::string_view s) {
    std::string out(s);
    for (char& c : out) c = ascii_lower(c);
    return out;
}

// Strict dotted-quad "a.b.c.d", decimal 0..255 without leading zeros; nullopt otherwise.
std::optional<uint32_t> parse_ipv4(std::string_view s) {
    uint32_t ip = 0;
    for (int part = 0; part < 4; ++part) {
        if (part > 0) {
            if (s.empty() || s.front() != '.') return std::nullopt;
            s.remove_prefix(1);
        }
        std::size_t n = 0;
        unsigned value = 0;
        while (n < s.size() && n < 4 && s[n] >= '0' && s[n] <= '9')
            value = value * 10 + (s[n++] - '0');
        if (n == 0 || n > 3 || value > 255 || (n > 1 && s[0] == '0')) return std::nullopt;
        s.remove_prefix(n);
        ip = (ip << 8) | value;
    }
    if (!s.empty()) return std::nullopt;
    return ip;
}

// ---------------------------------------------------------------------------------------------
// Lexer: the token rules of asLib_lex.l.

enum class Tok {
    end,
    lparen,
    rparen,
    lbrace,
    rbrace,
    comma,
    integer, // digits only
    string,  // bare name or quoted string (quotes removed, escapes kept as written)
    kw_uag,
    kw_hag,
    kw_asg,
    kw_rule,
    kw_calc,
    kw_inp, // INPA .. INPL
};

struct Token {
    Tok kind = Tok::end;
    std::string text;
    bool quoted = false;
    int line = 1;
    int col = 1;
};

bool is_name_char(char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
           (c != '\0' && std::strchr("_-+:.[]<>;", c) != nullptr);
}

class Lexer {
public:
    Lexer(std::string_view text, const std::string& file)
        : text_(text)
        , file_(file) {}

    const Token& peek() {
        if (!peeked_) {
            peeked_ = scan();
        }
        return *peeked_;
    }
    Token next() {
        Token t = peek();
        peeked_.reset();
        return t;
    }

    [[noreturn]] void fail(int line, int col, const std::string& msg) const {
        throw Error(SB() << SourceLoc{file_, line, col}.str() << ": " << msg);
    }
    [[noreturn]] void fail(const Token& at, const std::string& msg) const {
        fail(at.line, at.col, msg);
    }
    std::string where(int line, int col) const { return SourceLoc{file_, line, col}.str(); }

private:
    char cur() const { return text_[pos_]; }
    bool at_end() const { return pos_ >= text_.size(); }
    void advance() {
        if (text_[pos_] == '\n') {
            ++line_;
            col_ = 1;
        } else {
            ++col_;
        }
        ++pos_;
    }

    Token scan() {
        for (;;) {
            if (at_end()) return Token{Tok::end, "", false, line_, col_};
            char c = cur();
            if (c == ' ' || c == '\t' || c == '\r' || c == '\n') {
                advance();
            } else if (c == '#') {
                while (!at_end() && cur() != '\n') advance();
            } else {
                break;
            }
        }
        Token t;
        t.line = line_;
        t.col = col_;
        char c = cur();
        switch (c) {
        case '(':
            t.kind = Tok::lparen;
            break;
        case ')':
            t.kind = Tok::rparen;
            break;
        case '{':
            t.kind = Tok::lbrace;
            break;
        case '}':
            t.kind = Tok::rbrace;
            break;
        case ',':
            t.kind = Tok::comma;
            break;
        default:
            break;
        }
        if (t.kind != Tok::end) {
            t.text = std::string(1, c);
            advance();
            return t;
        }
        if (c == '"') return scan_quoted(t);
        if (is_name_char(c)) return scan_name(t);
        if (c == '$') fail(t, "invalid character '$' (macro substitution is not supported)");
        if (static_cast<unsigned char>(c) >= 0x20 && static_cast<unsigned char>(c) < 0x7f) {
            fail(t, SB() << "invalid character '" << c << "'");
        }
        const auto byte = static_cast<unsigned char>(c);
        constexpr std::string_view kHexDigits = "0123456789abcdef";
        fail(t, SB() << "invalid character 0x" << kHexDigits[byte >> 4] << kHexDigits[byte & 0xf]);
    }

    Token scan_quoted(Token t) {
        advance(); // opening quote
        std::size_t start = pos_;
        for (;;) {
            if (at_end()) fail(t, "unterminated quoted string");
            char c = cur();
            if (c == '"') break;
            if (c == '\n') fail(t, "newline in quoted string, closing quote missing");
            if (c == '\\') {
                advance();
                if (at_end()) fail(t, "unterminated quoted string");
                if (cur() == '\n') fail(t, "newline in quoted string, closing quote missing");
            }
            advance();
        }
        t.kind = Tok::string;
        t.quoted = true;
        t.text = std::string(text_.substr(start, pos_ - start));
        advance(); // closing quote
        return t;
    }

    Token scan_name(Token t) {
        std::size_t start = pos_;
        while (!at_end() && is_name_char(cur())) advance();
        t.text = std::string(text_.substr(start, pos_ - start));
        bool digits = true;
        for (char d : t.text) digits = digits && d >= '0' && d <= '9';
        if (digits) {
            t.kind = Tok::integer;
        } else if (t.text == "UAG") {
            t.kind = Tok::kw_uag;
        } else if (t.text == "HAG") {
            t.kind = Tok::kw_hag;
        } else if (t.text == "ASG") {
            t.kind = Tok::kw_asg;
        } else if (t.text == "RULE") {
            t.kind = Tok::kw_rule;
        } else if (t.text == "CALC") {
            t.kind = Tok::kw_calc;
        } else if (t.text.size() == 4 && t.text.compare(0, 3, "INP") == 0 && t.text[3] >= 'A' &&
                   t.text[3] <= 'L') {
            t.kind = Tok::kw_inp;
        } else {
            t.kind = Tok::string;
        }
        return t;
    }

    std::string_view text_;
    const std::string& file_;
    std::size_t pos_ = 0;
    int line_ = 1;
    int col_ = 1;
    std::optional<Token> peeked_;
};

std::string describe(const Token& t) {
    switch (t.kind) {
    case Tok::end:
        return "end of file";
    case Tok::integer:
        return SB() << "integer '" << t.text << "'";
    case Tok::string:
        return t.quoted ? std::string(SB() << "\"" << t.text << "\"")
                        : std::string(SB() << "'" << t.text << "'");
    case Tok::kw_uag:
    case Tok::kw_hag:
    case Tok::kw_asg:
    case Tok::kw_rule:
    case Tok::kw_calc:
    case Tok::kw_inp:
        return SB() << "keyword '" << t.text << "'";
    default:
        return SB() << "'" << t.text << "'";
    }
}

// ---------------------------------------------------------------------------------------------
// Parser: the grammar of asLib.y, with asLibRoutines.c's checks done while parsing.

struct DefinedAt {
    std::size_t index = 0;
    int line = 0;
    int col = 0;
};

class Parser {
public:
    Parser(std::string_view text, const std::string& file)
        : lex_(text, file) {
        config_.groups.emplace(std::string(kDefaultGroup), AccessConfig::Group{});
    }

    AccessConfig run() {
        if (lex_.peek().kind == Tok::end) {
            lex_.fail(lex_.peek(), "expected UAG, HAG or ASG, got end of file (an access "
                                   "security file needs at least one definition)");
        }
        for (;;) {
            Token t = lex_.next();
            switch (t.kind) {
            case Tok::end:
                return std::move(config_);
            case Tok::kw_uag:
                parse_uag();
                break;
            case Tok::kw_hag:
                parse_hag();
                break;
            case Tok::kw_asg:
                parse_asg();
                break;
            default:
                lex_.fail(t, SB() << "expected UAG, HAG or ASG, got " << describe(t));
            }
        }
    }

private:
    Token expect(Tok kind, const std::string& what, const std::string& context) {
        Token t = lex_.next();
        if (t.kind != kind) {
            lex_.fail(t, SB() << "expected " << what << " " << context << ", got " << describe(t));
        }
        return t;
    }

    // A name: bare word or quoted string (asLib's tokenSTRING).
    Token expect_name(const std::string& what, const std::string& context) {
        Token t = lex_.next();
        if (t.kind == Tok::string) return t;
        std::string hint;
        if (t.kind == Tok::integer) {
            hint = " (a bare number is not a name; quote it: \"" + t.text + "\")";
        } else if (t.kind != Tok::end && t.kind >= Tok::kw_uag) {
            hint = " (quote it to use it as a name: \"" + t.text + "\")";
        }
        lex_.fail(t,
                  SB() << "expected " << what << " " << context << ", got " << describe(t) << hint);
    }

    // "(" name ")" after UAG/HAG/ASG.
    Token parse_head(std::string_view keyword) {
        std::string ctx = SB() << "after " << keyword;
        expect(Tok::lparen, "'('", ctx);
        Token name = expect_name("a group name", ctx);
        expect(Tok::rparen, "')'", SB() << "after " << keyword << " name");
        return name;
    }

    // "{" member ["," member]... "}", already positioned at "{".
    std::vector<Token> parse_member_list(const std::string& what, const std::string& context) {
        lex_.next(); // '{'
        if (lex_.peek().kind == Tok::rbrace) {
            lex_.fail(lex_.peek(), SB() << "empty {} list " << context
                                        << " (omit the braces for an empty group)");
        }
        std::vector<Token> members;
        for (;;) {
            members.push_back(expect_name(what, context));
            Token t = lex_.next();
            if (t.kind == Tok::rbrace) return members;
            if (t.kind != Tok::comma) {
                lex_.fail(t, SB() << "expected ',' or '}' " << context << ", got " << describe(t));
            }
        }
    }

    void check_duplicate(const std::map<std::string, DefinedAt, std::less<>>& index,
                         const Token& name, std::string_view keyword) {
        auto it = index.find(name.text);
        if (it != index.end()) {
            lex_.fail(name, SB() << "duplicate " << keyword << " '" << name.text
                                 << "' (first defined at "
                                 << lex_.where(it->second.line, it->second.col) << ")");
        }
    }

    void parse_uag() {
        Token name = parse_head("UAG");
        check_duplicate(uag_index_, name, "UAG");
        uag_index_[name.text] = DefinedAt{config_.uags.size(), name.line, name.col};
        AccessConfig::Uag uag;
        uag.name = name.text;
        if (lex_.peek().kind == Tok::lbrace) {
            for (const Token& user :
                 parse_member_list("a user name", SB() << "in UAG '" << name.text << "'")) {
                uag.users.insert(user.text); // a repeated user is harmless, as in asLib
            }
        }
        config_.uags.push_back(std::move(uag));
    }

    void parse_hag() {
        Token name = parse_head("HAG");
        check_duplicate(hag_index_, name, "HAG");
        hag_index_[name.text] = DefinedAt{config_.hags.size(), name.line, name.col};
        AccessConfig::Hag hag;
        hag.name = name.text;
        if (lex_.peek().kind == Tok::lbrace) {
            for (const Token& host :
                 parse_member_list("a host name", SB() << "in HAG '" << name.text << "'")) {
                hag.hosts_lower.insert(to_lower(host.text));
                if (auto ip = parse_ipv4(host.text)) hag.ipv4.insert(*ip);
            }
        }
        config_.hags.push_back(std::move(hag));
    }

    void parse_asg() {
        Token name = parse_head("ASG");
        auto it = config_.groups.find(name.text);
        if (it == config_.groups.end()) {
            it = config_.groups.emplace(name.text, AccessConfig::Group{}).first;
        } else if (!(name.text == kDefaultGroup && it->second.rules.empty())) {
            // asLib (asAsgAdd): DEFAULT may be reopened only while it has no rules.
            auto first = asg_defined_at_.find(name.text);
            lex_.fail(name, SB() << "duplicate ASG '" << name.text << "' (first defined at "
                                 << lex_.where(first->second.line, first->second.col) << ")");
        }
        asg_defined_at_.try_emplace(name.text, DefinedAt{0, name.line, name.col});
        if (lex_.peek().kind != Tok::lbrace) return;
        lex_.next();
        std::string ctx = SB() << "in ASG '" << name.text << "'";
        if (lex_.peek().kind == Tok::rbrace) {
            lex_.fail(lex_.peek(), SB() << "empty {} body " << ctx << " (omit the braces for a "
                                        << "group without rules)");
        }
        for (;;) {
            Token t = lex_.next();
            if (t.kind == Tok::rbrace) return;
            if (t.kind == Tok::kw_rule) {
                it->second.rules.push_back(parse_rule(name.text));
            } else if (t.kind == Tok::kw_inp) {
                lex_.fail(t, SB() << t.text << "(...) " << ctx
                                  << ": CALC and INPx rules are not supported");
            } else {
                lex_.fail(t, SB() << "expected RULE or '}' " << ctx << ", got " << describe(t));
            }
        }
    }

    AccessConfig::Rule parse_rule(const std::string& asg) {
        std::string ctx = SB() << "in RULE of ASG '" << asg << "'";
        AccessConfig::Rule rule;
        expect(Tok::lparen, "'('", "after RULE");
        Token level = lex_.next();
        if (level.kind != Tok::integer) {
            lex_.fail(level, SB() << "expected a rule level (0 or 1) " << ctx << ", got "
                                  << describe(level));
        }
        errno = 0;
        long value = std::strtol(level.text.c_str(), nullptr, 10);
        if (errno == ERANGE || value > INT_MAX) {
            lex_.fail(level, SB() << "rule level " << level.text << " is out of range " << ctx);
        }
        rule.level = static_cast<int>(value);
        expect(Tok::comma, "','", SB() << "after the rule level " << ctx);
        Token right = expect_name("an access right (NONE, READ, WRITE or RPC)", ctx);
        if (right.text == "NONE") {
            rule.right = Right::none;
        } else if (right.text == "READ") {
            rule.right = Right::read;
        } else if (right.text == "WRITE") {
            rule.right = Right::write;
        } else if (right.text == "RPC") {
            rule.right = Right::rpc;
        } else {
            lex_.fail(right, SB() << "access right must be NONE, READ, WRITE or RPC, got "
                                  << describe(right));
        }
        Token t = lex_.next();
        if (t.kind == Tok::comma) {
            Token option = expect_name("TRAPWRITE or NOTRAPWRITE", ctx);
            if (option.text == "TRAPWRITE") {
                rule.trap_write = true;
            } else if (option.text != "NOTRAPWRITE") {
                lex_.fail(option, SB() << "rule option must be TRAPWRITE or NOTRAPWRITE, got "
                                       << describe(option));
            }
            t = lex_.next();
        }
        if (t.kind != Tok::rparen) {
            lex_.fail(t, SB() << "expected ')' to close RULE " << ctx << ", got " << describe(t));
        }
        if (lex_.peek().kind != Tok::lbrace) return rule;
        lex_.next();
        if (lex_.peek().kind == Tok::rbrace) {
            lex_.fail(lex_.peek(), SB() << "empty {} body " << ctx
                                        << " (omit the braces for a rule that applies to all)");
        }
        for (;;) {
            Token item = lex_.next();
            if (item.kind == Tok::rbrace) return rule;
            if (item.kind == Tok::kw_uag) {
                parse_rule_refs(uag_index_, "UAG", ctx, rule.uags);
            } else if (item.kind == Tok::kw_hag) {
                parse_rule_refs(hag_index_, "HAG", ctx, rule.hags);
            } else if (item.kind == Tok::kw_calc) {
                lex_.fail(item,
                          SB() << "CALC(...) " << ctx << ": CALC and INPx rules are not supported");
            } else {
                lex_.fail(item, SB() << "expected UAG(...), HAG(...) or '}' " << ctx << ", got "
                                     << describe(item));
            }
        }
    }

    // "(" name ["," name]... ")" after UAG/HAG inside a RULE body; names must be defined above.
    void parse_rule_refs(const std::map<std::string, DefinedAt, std::less<>>& index,
                         std::string_view keyword, const std::string& ctx,
                         std::vector<std::size_t>& out) {
        expect(Tok::lparen, "'('", SB() << "after " << keyword << " " << ctx);
        for (;;) {
            Token name = expect_name(SB() << "a " << keyword << " name", ctx);
            auto it = index.find(name.text);
            if (it == index.end()) {
                lex_.fail(name, SB() << "undefined " << keyword << " '" << name.text << "' " << ctx
                                     << " (a " << keyword
                                     << " must be defined before the ASG that uses it)");
            }
            out.push_back(it->second.index);
            Token t = lex_.next();
            if (t.kind == Tok::rparen) return;
            if (t.kind != Tok::comma) {
                lex_.fail(t, SB() << "expected ',' or ')' in " << keyword << "(...) " << ctx
                                  << ", got " << describe(t));
            }
        }
    }

    Lexer lex_;
    AccessConfig config_;
    std::map<std::string, DefinedAt, std::less<>> uag_index_;
    std::map<std::string, DefinedAt, std::less<>> hag_index_;
    std::map<std::string, DefinedAt, std::less<>> asg_defined_at_;
};

} // namespace

AccessSecurity::AccessSecurity() = default;

AccessSecurity::AccessSecurity(std::shared_ptr<const detail::AccessConfig> config)
    : config_(std::move(config)) {}

AccessSecurity AccessSecurity::parse(std::string_view text, const std::string& filename) {
    Parser parser(text, filename);
    return AccessSecurity(std::make_shared<const AccessConfig>(parser.run()));
}

AccessSecurity AccessSecurity::load_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        throw Error(SB() << path << ": cannot open access security file: " << std::strerror(errno));
    }
    std::ostringstream content;
    content << in.rdbuf();
    if (in.bad()) throw Error(SB() << path << ": cannot read access security file");
    return parse(content.str(), path);
}

bool AccessSecurity::enabled() const {
    return config_ != nullptr;
}

unsigned AccessSecurity::rights(std::string_view asg, int field_level, std::string_view user,
                                std::string_view host, std::string_view peer_ip) const {
    if (!config_) return kAccessRead | kAccessWrite;
    auto group = config_->groups.find(asg);
    if (group == config_->groups.end()) group = config_->groups.find(kDefaultGroup);

    const std::string host_lower = to_lower(host);
    const std::optional<uint32_t> peer = parse_ipv4(peer_ip);
    const auto in_uag = [&](std::size_t i) { return config_->uags[i].users.contains(user); };
    const auto in_hag = [&](std::size_t i) {
        const AccessConfig::Hag& hag = config_->hags[i];
        return hag.hosts_lower.contains(host_lower) || (peer && hag.ipv4.contains(*peer));
    };

    unsigned access = kAccessNone;
    for (const AccessConfig::Rule& rule : group->second.rules) {
        const unsigned bits = ca_bits(rule.right);
        if ((bits & ~access) == 0) continue; // grants nothing new
        if (field_level > rule.level) continue;
        if (!rule.uags.empty() && std::none_of(rule.uags.begin(), rule.uags.end(), in_uag)) {
            continue;
        }
        if (!rule.hags.empty() && std::none_of(rule.hags.begin(), rule.hags.end(), in_hag)) {
            continue;
        }
        access |= bits;
    }
    return access;
}

bool AccessSecurity::has_group(std::string_view asg) const {
    if (!config_) return false;
    return asg.empty() || config_->groups.contains(asg);
}

std::vector<std::string> AccessSecurity::groups() const {
    std::vector<std::string> names;
    if (!config_) return names;
    names.reserve(config_->groups.size());
    for (const auto& [name, group] : config_->groups) names.push_back(name);
    return names;
}

} // namespace beamctl::ca
