// Tokens of the PLC language and ExprTk's token passes (true/false, operator joining, implicit
// multiplication) plus ECMC's `VAR name : address; END_VAR` aliases. Compile-time only.
#pragma once

#include "plc/source.hpp"

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::plc::detail {

enum class Tok : std::uint8_t {
    end,
    number,
    symbol, // names, keywords, `&`, `|`, `~`, `[*]`
    string,
    assign, // :=
    add_assign,
    sub_assign,
    mul_assign,
    div_assign,
    mod_assign,
    swap, // <=>
    lt,
    le,
    gt,
    ge,
    eq, // = or ==
    ne, // != or <>
    add,
    sub,
    mul,
    div,
    mod,
    pow,
    comma,
    semicolon,
    lparen,
    rparen,
    lbracket,
    rbracket,
    lbrace,
    rbrace,
    question,
    colon,
    bang,
};

const char* to_string(Tok t);

struct Token {
    Tok type = Tok::end;
    std::string text;      // symbol name, unescaped string, operator spelling
    double value = 0;      // number
    int line = -1;         // preprocessed line (Source::lines)
    int offset = 0;        // byte offset in that line's text
    bool inserted = false; // an implicit '*'
};

// Lower-case copy (keywords and built-ins are case-insensitive, as in ExprTk).
std::string lower(std::string_view s);

// Lexes preprocessed lines [first, last) and applies the token passes; `aliases` enables VAR
// blocks (the program, not libraries). The result ends with a Tok::end token.
std::vector<Token> lex(const Source& src, int first, int last, bool aliases, Diagnostics& diags);

} // namespace beamctl::plc::detail
