// What an mca record drives (synApps' devMcaAsyn messages, drvMca.h): set-up, start, stop, erase,
// status (elapsed real and live time, counts in the preset region, acquiring) and the spectrum.
// A device is bound to the record's INP "@<name>" (an IOC's detectors) or given to it in tests.
// Threading: the database thread (the record's processing).
#pragma once

#include "pv/link.hpp"

#include <cstdint>

namespace beamctl::detector {

enum class McaMode : uint16_t { Pha = 0, Mcs = 1, List = 2 };

class McaDevice : public pv::LinkDevice {
public:
    // The record's acquisition set-up (presets of 0 are off).
    struct Setup {
        int32_t nuse = 0;           // channels in use
        double prtm = 0, pltm = 0;  // preset real / live time [s]
        double pct = 0;             // preset counts in channels pctl..pcth
        int32_t pctl = 0, pcth = 0;
        int32_t pswp = 1;           // MCS: preset sweeps
        double dwel = 1;            // MCS: dwell time per channel [s]
        McaMode mode = McaMode::Pha;
    };
    struct Status {
        double real = 0, live = 0; // elapsed [s]
        double dwell = 1;          // actual dwell time [s]
        int32_t total = 0;         // counts in the preset region (ACT)
        bool acquiring = false;
    };
    // false: the device refused (the record sets NACK).
    virtual bool setup(const Setup& s) = 0;
    // Whether the device acquires in this MODE (a put of another MODE is refused).
    virtual bool supports(McaMode m) const {
        (void)m;
        return true;
    }
    virtual bool start() = 0;
    virtual bool stop() = 0;
    virtual bool erase() = 0;
    // The status now (a simulated detector acquires up to now first).
    virtual bool status(Status& s) = 0;
    // The spectrum's first n channels into `data`; returns how many it had (NORD).
    virtual uint32_t read(int32_t* data, uint32_t n) = 0;

    bool read(double&) override { return false; }
    bool write(double) override { return false; }
};

} // namespace beamctl::detector
