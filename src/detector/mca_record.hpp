// synApps' mca record (mca's mcaRecord.c, docs/mcaRecord.html; specs/records.md §4): a spectrum
// (VAL, NUSE of NMAX channels, FTVL LONG), acquisition commands STRT / ERST / STOP / ERAS / READ,
// presets PRTM / PLTM / PCT (PCTL..PCTH) / PSWP, status ERTM ELTM ACT DTIM IDTIM ACQG, calibration
// CALO CALS CALQ TTH EGU (stored only), and 32 regions of interest R<n>LO/HI/BG/IP and their sums
// R<n> (total), R<n>N (net of a straight background), preset R<n>P, name R<n>NM; BG holds the
// background lines.
// Device support: INP "@<name>" bound to a detector::McaDevice (an IOC's simulated detector);
// every processing reads the device's status, reads the spectrum when acquisition ended (or READ),
// and sums the ROIs. As mcaRecord.c, the forward link and a put-callback that started an
// acquisition complete when the acquisition ends (ACQG 1 -> 0).
// Threading: the database thread, as every record.
#pragma once

#include "detector/mca_device.hpp"
#include "pv/record.hpp"

namespace beamctl::detector {

// Adds the record type "mca" (idempotent).
void register_detector_records(pv::RecordTypes& types);

// Tests: gives an mca record its device directly (without a link binder); false if `r` is not an
// mca record.
bool set_mca_device(pv::Record& r, McaDevice* device);

} // namespace beamctl::detector
