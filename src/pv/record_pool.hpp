// Storage of records (Record::operator new/delete). A large database is loaded by parsing its
// file, creating its records and freeing the parsed file; with records on the general heap, they
// land in the holes the parser's temporaries left, and freeing the parsed file then leaves holes of
// its own between them that the process keeps resident (about 0.6 kB per record measured on the
// chain benchmark). Records here come from blocks of their own, one free list per size, so they
// stay packed and the parser's memory is one free region the allocator reuses or returns.
// Threading: any thread (a mutex; records are created at load and removed rarely, never on the
// RT path). Built with AddressSanitizer, records use the general heap so that ASan sees them.
#pragma once

#include <cstddef>

namespace beamctl::pv::record_pool {

void* allocate(std::size_t size);
void deallocate(void* p, std::size_t size);

} // namespace beamctl::pv::record_pool
