"""Across machines: two servers in two network namespaces, a client in a third that finds both by
broadcast name search (ca-protocol.md §2, §8), with the servers' broadcast beacons reaching it through
a `beamctl ca-repeater` in its namespace. Skipped (with the reason) where namespaces cannot be made."""

import json
import os
import random
import subprocess
import time

import pytest

from conftest import BEAMCTL, PYTHON, IocServer, require_binary


def ip(*args, check=True):
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=20, check=check)


class Net:
    """A bridge in its own namespace and one veth-connected namespace per host."""

    def __init__(self, hosts):
        tag = "%06x" % random.randrange(1 << 24)
        self.br_ns = f"bcbr{tag}"
        self.hosts = {h: f"bc{h}{tag}" for h in hosts}
        self.subnet = f"10.{random.randrange(1, 255)}.{random.randrange(0, 255)}"
        self.addr = {h: f"{self.subnet}.{i + 1}" for i, h in enumerate(hosts)}
        self.bcast = f"{self.subnet}.255"
        self.created = []

    def up(self):
        ip("netns", "add", self.br_ns)
        self.created.append(self.br_ns)
        ip("-n", self.br_ns, "link", "add", "br0", "type", "bridge")
        ip("-n", self.br_ns, "link", "set", "br0", "up")
        for i, (h, ns) in enumerate(self.hosts.items()):
            ip("netns", "add", ns)
            self.created.append(ns)
            ip("-n", ns, "link", "set", "lo", "up")
            ip("-n", self.br_ns, "link", "add", f"v{i}", "type", "veth", "peer", "name", "eth0",
               "netns", ns)
            ip("-n", self.br_ns, "link", "set", f"v{i}", "master", "br0")
            ip("-n", self.br_ns, "link", "set", f"v{i}", "up")
            ip("-n", ns, "addr", "add", f"{self.addr[h]}/24", "brd", "+", "dev", "eth0")
            ip("-n", ns, "link", "set", "eth0", "up")

    def down(self):
        for ns in reversed(self.created):
            ip("netns", "del", ns, check=False)


class NsRepeater(IocServer):
    """`beamctl ca-repeater` on the default port 5065 inside a namespace."""

    def __init__(self, workdir, netns):
        super().__init__(workdir, [], 0, name="ns_repeater", extra_env={"EPICS_CA_REPEATER_PORT": "5065"})
        self.ns = netns

    def argv(self):
        return ["ip", "netns", "exec", self.ns, str(BEAMCTL), "ca-repeater"]


CLIENT = r"""
import json, sys, time, epics
from epics import ca
names = sys.argv[1:]
chids = [ca.create_channel(n, connect=False, auto_cb=False) for n in names]
t0 = time.time()
while time.time() - t0 < 20 and not all(ca.isConnected(c) for c in chids):
    ca.poll(0.05)
out = {}
for n, c in zip(names, chids):
    if ca.isConnected(c):
        out[n] = {"value": ca.get(c), "host": ca.host_name(c)}
    else:
        out[n] = None
print(json.dumps(out))
"""


@pytest.mark.parametrize("intf", ["wildcard", "interface_ip"])
def test_broadcast_search_across_namespaces(require_netns, tmp_path, intf):
    require_binary()
    net = Net(["a", "b", "c"])
    servers = []
    try:
        net.up()
        tag = net.br_ns[4:]
        for h, val in (("a", 11.5), ("b", 22.5)):
            db = tmp_path / f"{h}.db"
            db.write_text(f'record(ai, "NS{tag}:{h}") {{ field(VAL, "{val}") field(PINI, "YES") }}\n')
            srv = IocServer(tmp_path, [db], 5064, netns=net.hosts[h], name=f"ns_{h}",
                            intf=None if intf == "wildcard" else net.addr[h],
                            extra_env={"EPICS_CAS_AUTO_BEACON_ADDR_LIST": "YES",
                                       "EPICS_CAS_BEACON_ADDR_LIST": None})
            servers.append(srv)
            srv.start()
        # the client host's repeater (else libca would spawn a caRepeater that outlives the test)
        rep = NsRepeater(tmp_path, net.hosts["c"])
        servers.append(rep)
        rep.start()
        env = {k: v for k, v in os.environ.items() if not k.startswith("EPICS_")}
        env.update({"EPICS_CA_AUTO_ADDR_LIST": "YES", "EPICS_CA_SERVER_PORT": "5064",
                    "EPICS_CA_REPEATER_PORT": "5065"})
        names = [f"NS{tag}:a", f"NS{tag}:b"]
        r = subprocess.run(["ip", "netns", "exec", net.hosts["c"], PYTHON, "-c", CLIENT, *names],
                           env=env, capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr[-2000:]
        assert "caRepeater" not in r.stderr, r.stderr[-2000:]
        res = json.loads(r.stdout.strip().splitlines()[-1])
        assert res[names[0]] is not None, f"server a not found by broadcast search: {res}"
        assert res[names[1]] is not None, f"server b not found by broadcast search: {res}"
        assert res[names[0]]["value"] == 11.5 and res[names[1]]["value"] == 22.5
        assert res[names[0]]["host"].startswith(net.addr["a"] + ":")
        assert res[names[1]]["host"].startswith(net.addr["b"] + ":")
        for s in servers:
            assert s.alive()
    finally:
        for s in servers:
            s.kill()
        net.down()
        time.sleep(0.05)
