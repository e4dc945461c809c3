/* A plugin built for another ABI version: beamctl must refuse it with a clear message. */
#include "beamctl/plugin.h"

static const beamctl_plugin plugin = {BEAMCTL_PLUGIN_ABI_VERSION + 41u, "future", "from the future", "", 1,
                                      0, 0, 0, 0, 0, {{0, 0, 0, 0}}, {{0, 0, 0}}};

const beamctl_plugin* beamctl_plugin_get(void) { return &plugin; }
