// Counts global operator new calls while enabled: RT rule 1 (the cycle allocates nothing) is
// checked by enabling it around many cycles and expecting 0.
#pragma once

namespace beamctl::test {
void count_allocations(bool on);
long allocations(); // since the last count_allocations(true)
} // namespace beamctl::test
