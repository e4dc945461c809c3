// Area detectors in an IOC (docs/detectors.md): each entry of `detectors.area_detector` is a
// simulated camera of the simulated beam (detector/sim_camera.hpp) behind areaDetector's PV sets
// with ADCore's names: the driver $(P)cam1: (ADBase, NDArrayBase), the image plugin $(P)image1:
// (NDPluginBase, NDStdArrays' ArrayData), the HDF5 file plugin $(P)HDF1: (NDFile, NDFileHDF5's
// default layout: daq/frame_file.hpp) and the statistics plugin $(P)Stats1: (NDStats).
// Acquire is ADCore's chain of records: Acquire (bo) -> SetAcquireBusy -> AcquireBusy (busy), and
// AcquireBusyCB -> ClearAcquireBusy -> AcquireBusy 0, so a put-callback on Acquire 1 completes when
// the acquisition and every plugin's work on its frames are done. Capture and WriteFile are busy
// records that complete when the file work is done.
// The camera integrates the beam over each exposure (the plant's BeamTally: the spot's mean centre,
// its motion blur, the slit's transmission) on the IOC loop's clock; the frames are rendered, their
// statistics computed and the files written on the detector's own worker thread.
// Threading: construction, bind() and start() at bring-up; poll() and the records on the IOC loop; one
// worker thread per detector (started by bind(), joined by the destructor).
#pragma once

#include "config/ioc_config.hpp"
#include "ethercat/sim/beam.hpp"
#include "pv/database.hpp"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace beamctl::ioc {

class IocAreaDetector {
public:
    // Makes the records (loaded into `db`); exposures on `clock` [s] (the IOC loop's, as poll()'s).
    // Throws Error naming the entry.
    IocAreaDetector(const config::IocConfig& cfg, pv::Database& db, std::function<double()> clock);
    ~IocAreaDetector();
    IocAreaDetector(const IocAreaDetector&) = delete;
    IocAreaDetector& operator=(const IocAreaDetector&) = delete;

    // The beam each detector sees: `beam_of(bus)` returns the tally source of a simulated bus's
    // plant beam (bus -1: the first with one), or nullptr (the detector sees no beam: dark frames).
    using BeamSource = std::function<ethercat::sim::BeamTally()>;
    void bind(const std::function<BeamSource(int bus)>& beam_of);
    // After the records are initialised: the initial texts and readbacks; starts the workers.
    void start();
    // IOC loop, every few ms: exposures at `now_s` [s] (the clock's time), the workers' results into PVs.
    void poll(double now_s);
    // Frames the workers still have to process or the IOC loop to take (tests wait for 0).
    std::size_t busy() const;
    // Jobs still at the workers (tests wait for 0 before the next poll).
    std::size_t busy_worker() const;

    std::size_t size() const { return units_.size(); }

private:
    struct Unit;
    struct Worker;

    void make_records(const config::AreaDetectorEntry& e, const std::string& prefix, pv::DbFile& f);
    void copy_readback(pv::Record& out, pv::Record& rbv);
    void hook(Unit& u);
    void apply_camera(Unit& u);
    void start(Unit& u, double now_s);
    void finish(Unit& u);
    void expose(Unit& u, double now_s);
    void take_results(Unit& u);
    void file_command(Unit& u, int kind);

    pv::Database& db_;
    std::vector<std::unique_ptr<Unit>> units_;
    std::function<double()> clock_;
};

// areaDetector's file name: `tmpl` as C's printf with (path, name, number) for its conversions,
// which must be at most two %s then at most one integer conversion (flags, width, precision of
// d, i, u, o, x, X) and %%. False with `why` for any other template (never handed to printf).
bool format_file_name(const std::string& tmpl, const std::string& path, const std::string& name, int number, std::string& out,
                      std::string& why);

} // namespace beamctl::ioc
