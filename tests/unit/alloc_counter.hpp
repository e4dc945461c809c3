// Counts global operator new calls while enabled: RT rule 1 (the cycle allocates nothing) is
// checked by enabling it around many cycles and expecting 0.
#pragma once

namespace beamctl::test {
// this_thread_only: count only the calling thread's (the cycle's, while a writer thread works).
void count_allocations(bool on, bool this_thread_only = false);
long allocations(); // since the last count_allocations(true)
} // namespace beamctl::test
