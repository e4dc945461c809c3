#include "plc/m2m.hpp"

#include "core/error.hpp"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/mman.h>
#include <unistd.h>

namespace beamctl::plc {

M2m::M2m(const std::string& name, int master) : name_(name), master_(master) {
    if (name.empty() || name.find('/') != std::string::npos || name.size() > 200)
        throw Error(SB() << "m2m: '" << name << "' should be a plain name (no '/')");
    if (master <= -kMaxMasters || master >= kMaxMasters)
        throw Error(SB() << "m2m: master index " << master << " is out of range (" << 1 - kMaxMasters << ".." << kMaxMasters - 1 << ")");
    std::string path = "/" + name;
    int fd = ::shm_open(path.c_str(), O_RDWR | O_CREAT, 0660);
    if (fd < 0) throw Error(SB() << "m2m: cannot open the shared memory /dev/shm/" << name << ": " << std::strerror(errno));
    struct stat st {};
    if (::fstat(fd, &st) == 0 && st.st_size < off_t(sizeof(Shared)) && ::ftruncate(fd, sizeof(Shared)) != 0) {
        int e = errno;
        ::close(fd);
        throw Error(SB() << "m2m: cannot size /dev/shm/" << name << ": " << std::strerror(e));
    }
    void* p = ::mmap(nullptr, sizeof(Shared), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    int e = errno;
    ::close(fd);
    if (p == MAP_FAILED) throw Error(SB() << "m2m: cannot map /dev/shm/" << name << ": " << std::strerror(e));
    s_ = static_cast<Shared*>(p); // a new object reads zeros: 0.0 values, nobody running
}

M2m::~M2m() {
    if (!s_) return;
    s_->running[master_ + kMaxMasters].store(0, std::memory_order_relaxed);
    s_->ec_ok[master_ + kMaxMasters].store(0, std::memory_order_relaxed);
    ::munmap(s_, sizeof(Shared));
}

uint32_t M2m::write(double index, double value) noexcept {
    if (!(index >= 0 && index < kElements)) return kIndexOutOfRange;
    uint64_t bits;
    std::memcpy(&bits, &value, 8);
    s_->values[int(index)].store(bits, std::memory_order_relaxed);
    return 0;
}

double M2m::read(double index, uint32_t& error) const noexcept {
    if (!(index >= 0 && index < kElements)) {
        error = kIndexOutOfRange;
        return 0;
    }
    uint64_t bits = s_->values[int(index)].load(std::memory_order_relaxed);
    double v;
    std::memcpy(&v, &bits, 8);
    return v;
}

void M2m::set_state(bool ec_ok) noexcept {
    s_->running[master_ + kMaxMasters].store(1, std::memory_order_relaxed);
    s_->ec_ok[master_ + kMaxMasters].store(ec_ok && master_ >= 0 ? 1 : 0, std::memory_order_relaxed);
}

int M2m::slot(double master) const noexcept {
    if (!(master > -kMaxMasters && master < kMaxMasters)) return -1;
    return int(std::lround(master)) + kMaxMasters;
}

double M2m::ioc_running(double master) const noexcept {
    int i = slot(master);
    return i < 0 ? -1 : s_->running[i].load(std::memory_order_relaxed);
}

double M2m::ioc_ec_ok(double master) const noexcept {
    int i = slot(master);
    if (i < 0) return -1;
    return master < 0 ? 0 : s_->ec_ok[i].load(std::memory_order_relaxed);
}

} // namespace beamctl::plc
