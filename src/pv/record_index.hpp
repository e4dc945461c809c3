// The name index of a Database: an open-addressing hash table of record pointers (linear probing,
// at most half full, backward-shift erase). One flat array instead of a node per record: 16 bytes
// per record rather than about 80, and no small allocations scattered among the records while a
// large database loads. Names are the records' own (Record::name()); the index owns nothing.
// Threading: the database's thread.
#pragma once

#include "pv/record.hpp"

#include <cstddef>
#include <functional>
#include <string_view>
#include <vector>

namespace beamctl::pv {

class RecordIndex {
public:
    Record* find(std::string_view name) const {
        if (slots_.empty()) return nullptr;
        for (std::size_t i = home(name);; i = next(i)) {
            Record* r = slots_[i];
            if (!r) return nullptr;
            if (r->name() == name) return r;
        }
    }
    // Adds r (its name must not be in the index yet).
    void insert(Record* r) {
        if (2 * (size_ + 1) > slots_.size()) grow();
        std::size_t i = home(r->name());
        while (slots_[i]) i = next(i);
        slots_[i] = r;
        ++size_;
    }
    // Removes the record of that name; returns it (nullptr if none).
    Record* erase(std::string_view name) {
        if (slots_.empty()) return nullptr;
        std::size_t i = home(name);
        while (slots_[i] && slots_[i]->name() != name) i = next(i);
        Record* r = slots_[i];
        if (!r) return nullptr;
        // backward shift: move later entries of the probe run into the hole when their home allows
        for (std::size_t j = next(i);; j = next(j)) {
            if (!slots_[j]) break;
            std::size_t h = home(slots_[j]->name());
            bool movable = i <= j ? (h <= i || h > j) : (h <= i && h > j);
            if (movable) {
                slots_[i] = slots_[j];
                i = j;
            }
        }
        slots_[i] = nullptr;
        --size_;
        return r;
    }
    std::size_t size() const { return size_; }

private:
    std::size_t home(std::string_view name) const { return std::hash<std::string_view>{}(name) & (slots_.size() - 1); }
    std::size_t next(std::size_t i) const { return (i + 1) & (slots_.size() - 1); }
    void grow() {
        std::vector<Record*> old(slots_.empty() ? 64 : 2 * slots_.size(), nullptr);
        old.swap(slots_);
        size_ = 0;
        for (Record* r : old)
            if (r) insert(r);
    }
    std::vector<Record*> slots_; // size a power of two (or empty)
    std::size_t size_ = 0;
};

} // namespace beamctl::pv
