// Local (UNIX stream) sockets of this process: the IOC shell (`beamctl shell`), the simulator's
// fault control (`beamctl sim --control`), and whatever else listens on a socket file. One policy
// for all of them (issue 19):
//   - the socket file is created with mode 0660 and belongs to the socket group: the group that
//     BEAMCTL_SOCKET_GROUP names, or this process's own group;
//   - a connection is accepted only from this process's user, root, or a process that has the
//     socket group among its groups; the kernel's word (SO_PEERCRED, /proc/<pid>/status) decides,
//     not the file mode, which anyone who owns the file can change;
//   - a socket file left by a crashed run (nobody answers on it) is replaced; a live server on the
//     path, or a path that is not a socket, is an error naming it.
// Threading: none of its own; call from the thread that owns the socket.
#pragma once

#include <string>
#include <sys/types.h>

namespace beamctl::core {

struct SocketGroup {
    gid_t gid = 0;
    std::string name; // "beamline", or the numeric gid when it has no name
};
// The socket group: BEAMCTL_SOCKET_GROUP (a group name or number), else the effective gid.
// Throws Error naming the variable for a group the system does not know.
SocketGroup socket_group();
// A group by name or number (a configuration's choice); `what` names the setting in the error.
SocketGroup socket_group_named(const std::string& name_or_gid, const std::string& what);

// Creates, binds (mode 0660, the socket group, or `group` when given) and listens on a UNIX stream
// socket at `path`. `what` names it in errors ("shell socket"). Throws Error.
int listen_local(const std::string& path, const std::string& what, int backlog, bool nonblocking,
                 const SocketGroup* group = nullptr);

// The process at the other end of an accepted connection.
struct Peer {
    pid_t pid = 0;
    uid_t uid = 0;
    gid_t gid = 0;
};
// True when the peer may use a socket of this process: its user, root, or a member of `group`.
// `peer` is filled in either way (uid -1 when the kernel did not say).
bool peer_allowed(int fd, const SocketGroup& group, Peer& peer);

} // namespace beamctl::core
