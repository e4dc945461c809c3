#include "ethercat/sim/sim_config.hpp"

#include "core/error.hpp"

#include <yaml-cpp/yaml.h>

#include <arpa/inet.h>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <fstream>
#include <netinet/in.h>
#include <poll.h>
#include <sstream>
#include <sys/socket.h>
#include <unistd.h>

namespace beamctl::ethercat::sim {
namespace {

std::string where(const std::string& file, const YAML::Node& n) {
    return SB() << file << ":" << n.Mark().line + 1 << ":" << n.Mark().column + 1;
}

void copy_bits(const uint8_t* src, uint32_t sb, uint8_t* dst, uint32_t db, uint32_t bits) {
    for (uint32_t i = 0; i < bits; ++i) {
        uint32_t s = sb + i, d = db + i;
        if (src[s >> 3] >> (s & 7) & 1) dst[d >> 3] |= uint8_t(1u << (d & 7));
        else dst[d >> 3] &= uint8_t(~(1u << (d & 7)));
    }
}

} // namespace

EntryLocation locate_entry(const DeviceDesc& d, std::string_view entry) {
    for (const auto& sm : d.sms) {
        if (sm.type != SmType::Outputs && sm.type != SmType::Inputs) continue;
        bool out = sm.type == SmType::Outputs;
        uint32_t bit = 0;
        for (auto& [smi, pdo_index] : d.pdo_assign) {
            if (smi != sm.index) continue;
            for (const auto& p : out ? d.rx_pdos : d.tx_pdos) {
                if (p.index != pdo_index) continue;
                for (const auto& e : p.entries) {
                    if (e.name == entry) return EntryLocation{sm.index, bit, e.bits, out};
                    bit += e.bits;
                }
            }
        }
    }
    throw Error(SB() << d.type << " has no process-data entry '" << entry << "'");
}

SimConfig SimConfig::load(const std::string& path, const Catalog& catalog) {
    std::ifstream f(path);
    if (!f) throw Error(SB() << path << ": cannot open simulator configuration: " << std::strerror(errno));
    std::stringstream ss;
    ss << f.rdbuf();
    return parse(ss.str(), path, catalog);
}

SimConfig SimConfig::parse(const std::string& text, const std::string& file, const Catalog& catalog) {
    YAML::Node root;
    try {
        root = YAML::Load(text);
    } catch (const YAML::ParserException& e) {
        throw Error(SB() << file << ":" << e.mark.line + 1 << ":" << e.mark.column + 1 << ": " << e.msg);
    }
    SimConfig c;
    if (!root || root.IsNull()) return c;
    if (!root.IsMap()) throw Error(SB() << where(file, root) << ": expected a mapping with slaves: and wiring:");
    for (auto kv : root) {
        std::string key = kv.first.as<std::string>();
        if (key != "slaves" && key != "wiring")
            throw Error(SB() << where(file, kv.first) << ": unknown key '" << key << "' (expected slaves, wiring)");
    }
    std::map<int, std::string> types;
    if (auto s = root["slaves"]) {
        if (!s.IsSequence()) throw Error(SB() << where(file, s) << ": slaves: should be a list");
        for (auto item : s) {
            if (!item.IsMap() || !item["position"] || !item["type"])
                throw Error(SB() << where(file, item) << ": a slave needs position: and type:");
            for (auto kv : item) {
                std::string k = kv.first.as<std::string>();
                if (k != "position" && k != "type")
                    throw Error(SB() << where(file, kv.first) << ": unknown key '" << k << "' in a slave");
            }
            int pos;
            try {
                pos = item["position"].as<int>();
            } catch (const YAML::Exception&) {
                throw Error(SB() << where(file, item["position"]) << ": position should be an integer");
            }
            std::string type = item["type"].as<std::string>();
            if (!catalog.find(type))
                throw Error(SB() << where(file, item["type"]) << ": unknown device type '" << type << "'");
            if (pos != int(c.slaves.size()))
                throw Error(SB() << where(file, item["position"]) << ": positions must be 0, 1, 2, ... in order (got "
                                 << pos << ", expected " << c.slaves.size() << ")");
            c.slaves.emplace_back(pos, type);
            types[pos] = type;
        }
    }
    if (auto w = root["wiring"]) {
        if (!w.IsSequence()) throw Error(SB() << where(file, w) << ": wiring: should be a list");
        for (auto item : w) {
            if (!item.IsMap() || !item["from"] || !item["to"])
                throw Error(SB() << where(file, item) << ": a wire needs from: and to:");
            Wire wire;
            auto parse_end = [&](const YAML::Node& n, int& slave, std::string& entry) {
                std::string s = n.as<std::string>();
                // "s3.binaryOutput01" or "ec0.s3.binaryOutput01"
                if (s.rfind("ec", 0) == 0 && s.find('.') != std::string::npos) s = s.substr(s.find('.') + 1);
                std::size_t dot = s.find('.');
                if (s.size() < 4 || s[0] != 's' || dot == std::string::npos)
                    throw Error(SB() << where(file, n) << ": '" << n.as<std::string>()
                                     << "' should look like s<position>.<entry>, e.g. s1.binaryOutput01");
                try {
                    slave = std::stoi(s.substr(1, dot - 1));
                } catch (...) {
                    throw Error(SB() << where(file, n) << ": bad slave position in '" << s << "'");
                }
                entry = s.substr(dot + 1);
                if (!c.slaves.empty() && !types.count(slave))
                    throw Error(SB() << where(file, n) << ": no slave at position " << slave);
            };
            parse_end(item["from"], wire.from_slave, wire.from_entry);
            parse_end(item["to"], wire.to_slave, wire.to_entry);
            if (!c.slaves.empty()) {
                try {
                    wire.from = locate_entry(*catalog.find(types[wire.from_slave]), wire.from_entry);
                    wire.to = locate_entry(*catalog.find(types[wire.to_slave]), wire.to_entry);
                } catch (const Error& e) {
                    throw Error(SB() << where(file, item) << ": " << e.what());
                }
                if (wire.from.bits != wire.to.bits)
                    throw Error(SB() << where(file, item) << ": " << wire.from_entry << " has " << int(wire.from.bits)
                                     << " bits but " << wire.to_entry << " has " << int(wire.to.bits));
                if (wire.to.output)
                    throw Error(SB() << where(file, item["to"]) << ": " << wire.to_entry
                                     << " is an output; a wire drives an input");
            }
            c.wiring.push_back(wire);
        }
    }
    return c;
}

void SimConfig::build(Segment& seg, const Catalog& catalog) const {
    for (auto& [pos, type] : slaves) seg.add(*catalog.find(type));
    std::vector<Wire> wires = wiring;
    for (auto& w : wires) { // resolve against the segment when the file named no slaves
        if (w.from_slave >= int(seg.size()) || w.to_slave >= int(seg.size()))
            throw Error(SB() << "wiring " << w.from_entry << " -> " << w.to_entry << ": no such slave position");
        w.from = locate_entry(seg.slave(w.from_slave).desc(), w.from_entry);
        w.to = locate_entry(seg.slave(w.to_slave).desc(), w.to_entry);
    }
    if (wires.empty()) return;
    seg.on_frame = [wires](Segment& s) {
        for (const Wire& w : wires) {
            Esc& from = s.slave(w.from_slave);
            Esc& to = s.slave(w.to_slave);
            uint8_t zero[8] = {};
            const uint8_t* src = from.outputs_valid() || !w.from.output ? from.sm_buffer(w.from.sm) : zero;
            copy_bits(src, from.outputs_valid() || !w.from.output ? w.from.bit : 0, to.sm_buffer(w.to.sm),
                      w.to.bit, w.to.bits);
        }
    };
}

UdpServer::UdpServer(Segment& seg, const std::string& bind_addr, uint16_t port) : seg_(seg) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    if (inet_pton(AF_INET, bind_addr.c_str(), &a.sin_addr) != 1)
        throw Error(SB() << "sim: '" << bind_addr << "' is not an IPv4 address");
    fd_ = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0 || bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
        throw Error(SB() << "sim: cannot bind UDP " << bind_addr << ":" << port << ": " << std::strerror(errno));
    socklen_t len = sizeof a;
    getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
}

UdpServer::~UdpServer() {
    if (fd_ >= 0) ::close(fd_);
}

bool UdpServer::serve_one(int timeout_ms) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) <= 0) return false;
    uint8_t buf[kMaxFrame + 64];
    sockaddr_in from{};
    socklen_t flen = sizeof from;
    ssize_t n = recvfrom(fd_, buf, sizeof buf, 0, reinterpret_cast<sockaddr*>(&from), &flen);
    if (n <= 0) return false;
    if (std::size_t(n) > kMaxFrame) {
        ++malformed;
        return true;
    }
    auto now = std::chrono::system_clock::now().time_since_epoch();
    int64_t ns = std::chrono::duration_cast<std::chrono::nanoseconds>(now).count() - 946684800LL * 1000000000LL;
    seg_.set_time(uint64_t(ns));
    ++frames;
    if (!seg_.process(buf, std::size_t(n))) return true; // lost on purpose
    sendto(fd_, buf, std::size_t(n), 0, reinterpret_cast<sockaddr*>(&from), flen);
    return true;
}

void UdpServer::run(const volatile bool& stop, int poll_ms) {
    while (!stop) serve_one(poll_ms);
}

} // namespace beamctl::ethercat::sim
