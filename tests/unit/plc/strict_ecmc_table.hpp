// Constructs for the strict ECMC mode (issue 18): code beamctl compiles, and whether ECMC's
// ExprTk compiles it too. Every verdict was checked against ExprTk 2025-01-01 (default parser
// settings, unknown names resolved to variables, as ECMC binds its variables) by
// bench/exprtk_strict_check, which runs this table whenever bench_plc's ExprTk reference is built.
#pragma once

namespace beamctl::plc::test {

struct StrictCase {
    const char* code;
    bool exprtk_accepts;
    const char* ecmc_spelling; // in beamctl's strict error (refused cases)
};

inline constexpr StrictCase kStrictCases[] = {
    // bare braces: a bracket around one expression to ExprTk
    {"{ var a := 1; x := a; };", false, "~{ ... }"},
    {"{ x := 1; };", false, "~{ ... }"},
    {"if (x) { { y := 1; }; };", false, "~{ ... }"},
    {"{};", false, "~{ ... }"},
    {"x := {1; 2};", false, "~{ ... }"},
    {"~{ var a := 1; x := a; };", true, ""},
    {"x := 1; ~{ var a := 1; x := a; }; ~{ var a := 2; y := a; };", true, ""},
    {"{ x := 1 };", true, ""},
    {"x := { var a := 1 };", true, ""},
    {"x := {y := 2} + [1] * (3);", true, ""},
    {"if (x) { var a := 1; x := a; } else { y := 2; };", true, ""},
    // empty statements
    {"x := y;;", false, "remove the ';'"},
    {";", false, "remove the ';'"},
    {"x := 1;\n;\ny := 2;", false, "remove the ';'"},
    {"x := y; /* c */ ;", false, "remove the ';'"},
    {"if (x) { y := 1; ; };", false, "remove the ';'"},
    {"if (x) { ; y := 1; };", false, "remove the ';'"},
    {"for (var i := 0; i < 1; i += 1) { ; };", false, "remove the ';'"},
    {"if (x) { y := 1; };;", false, "remove the ';'"},
    {"switch { case x > 1 : y := 1;; };", false, "remove the ';'"},
    {"x := 1; # a comment\ny := 2;", true, ""},
    {"if (x) { y := 1; }\nelse { z := 1; };", true, ""},
    // for without an initialiser
    {"for (;;) { break; };", false, "while (condition)"},
    {"for (; i < 3; i += 1) { x := 1; };", false, "while (condition)"},
    {"for (var i := 0; ; i += 1) { break; };", true, ""},
    {"for (var i := 0; i < 3; ) { i += 1; };", true, ""},
    {"for (i := 0; i < 3; i += 1) { x := 1; };", true, ""},
    // switch and [*]: every case and default ends with ';'
    {"switch { case x > 1 : y := 1 };", false, "case c : ...;"},
    {"switch { case x > 1 : y := 1 case x < 1 : y := 2; };", false, "case c : ...;"},
    {"switch { case 1 : { y := 1; z := 2; } };", false, "case c : ...;"},
    {"switch { case x > 1 : y := 1; default : y := 2 };", false, "default : ...;"},
    {"switch { case x > 1 : y := 1; default : { y := 3; } };", false, "default : ...;"},
    {"[*] { case x > 1 : y := 1 };", false, "case c : ...;"},
    {"[*] { case x > 1 : { y := 1; } };", false, "case c : ...;"},
    {"switch { case x > 1 : y := 1; case x < 1 : y := 2; default : y := 3; };", true, ""},
    {"switch { case x > 1 : { y := 1; }; default : { y := 3; }; };", true, ""},
    {"[*] { case x > 1 : y := 1; case x < 1 : y := 2; };", true, ""},
    // numbers side by side
    {"x := 1 2;", false, "an operator or ';'"},
    {"x := 1.5 2.5;", false, "an operator or ';'"},
    {"x := 2 y + y 2 + (y) 2 + 2 (3) + 2 pi;", true, ""},
    // function definitions belong in library files
    {"function f(a) { return [a]; };", false, "library file"},
    // accepted by both (a sample of the language)
    {"if (x) y := 1; else z := 2;", true, ""},
    {"if (x) { x := 1; } else if (y) { y := 2; } else { z := 3; };", true, ""},
    {"if (x) { y := 1; } if (z) { y := 2; };", true, ""},
    {"x := y == 1 ? 2 : y ? 3 : 4;", true, ""},
    {"while (x < 10) { x += 1; };", true, ""},
    {"repeat x += 1; until (x > 3);", true, ""},
    {"for (var i := 0; i < 3; i += 1) { if (i == 1) continue; x += i; };", true, ""},
    {"var v[3] := {1, 2, 3}; x := v[0] + v[] + sum(v); v[1] := 4; v := v * 2;", true, ""},
    {"var a := 1; var b := 2; a <=> b;", true, ""},
    {"x := 1; return [x];", true, ""},
    {"x := not(y) + (y and z) + (y or z) + (y xor z) + (y nand z) + (y nor z) + (y xnor z);", true, ""},
    {"x := y & z | w; x := y <> 1; x := y = 1; x := -y ^ 2 + y % 2;", true, ""},
    {"x := 1 // comment\n; y := 2 /* block */;", true, ""},
    {"x := clamp(0, y, 1) + inrange(0, y, 1) + roundn(y, 2) + hypot(y, z) + atan2(y, z);", true, ""},
    {"println('a', x, 'b'); print(x);", true, ""},
};

} // namespace beamctl::plc::test
