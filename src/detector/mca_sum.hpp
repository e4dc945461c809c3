// The sum of a multi-element detector's spectra behind an mca record of its own ($(P)mcaSum): its
// set-up, start, stop and erase go to every element (so its presets acquire them all), its status
// is theirs together (the longest real time, the mean live time, the totals added, acquiring while
// any is) and its spectrum is theirs added channel by channel.
// Threading: the database thread (the record's processing).
#pragma once

#include "detector/mca_device.hpp"

#include <string>
#include <vector>

namespace beamctl::detector {

class McaSum : public McaDevice {
public:
    explicit McaSum(std::vector<McaDevice*> elements, std::string name = "sum");

    bool setup(const Setup& s) override;
    bool supports(McaMode m) const override { // what every element acquires in
        for (const McaDevice* e : elements_)
            if (!e->supports(m)) return false;
        return true;
    }
    bool start() override;
    bool stop() override;
    bool erase() override;
    bool status(Status& s) override;
    uint32_t read(int32_t* data, uint32_t n) override;
    std::string describe() const override;

private:
    std::vector<McaDevice*> elements_;
    std::string name_;
    std::vector<int32_t> part_;
    std::vector<int64_t> sum_;
};

} // namespace beamctl::detector
