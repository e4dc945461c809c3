/* An example beamctl plugin: a gain set from the configuration, a function using it, a clamp,
 * a cycle counter (realtime callback) and two constants. Build:
 *   cc -shared -fPIC -I include -o example_plugin.so examples/plugins/example_plugin.c
 * Use from PLC code: `static.y := ex_scale(ax1.enc.actpos);`  `static.n := ex_cycles();`
 */
#include "beamctl/plugin.h"

#include <stdlib.h>
#include <string.h>

static double gain = 1.0;
static double cycles = 0;
static int entered = 0;

/* config: "GAIN=2.5" */
static int construct(const char* config) {
    const char* g = config ? strstr(config, "GAIN=") : NULL;
    if (g) gain = strtod(g + 5, NULL);
    return gain == gain ? 0 : 1; /* NaN refused */
}
static void destruct(void) {}
static int rt_enter(void) { entered = 1; cycles = 0; return 0; }
static int rt_exit(void) { entered = 0; return 0; }
static int realtime(int error_code) { (void)error_code; cycles += 1; return 0; }

static double ex_scale(const double* a) { return gain * a[0]; }
static double ex_clamp(const double* a) { return a[0] < a[1] ? a[1] : a[0] > a[2] ? a[2] : a[0]; }
static double ex_cycles(const double* a) { (void)a; return cycles; }
static double ex_entered(const double* a) { (void)a; return entered; }

static const beamctl_plugin plugin = {
    BEAMCTL_PLUGIN_ABI_VERSION,
    "example",
    "Example plugin: a configurable gain, a clamp and a cycle counter",
    "GAIN=<number> (default 1)",
    1,
    construct,
    destruct,
    rt_enter,
    rt_exit,
    realtime,
    {
        {"ex_scale", "gain x value (GAIN from the configuration)", 1, ex_scale},
        {"ex_clamp", "value clamped to [low, high]", 3, ex_clamp},
        {"ex_cycles", "cycles since rt_enter", 0, ex_cycles},
        {"ex_entered", "1 between rt_enter and rt_exit", 0, ex_entered},
        {NULL, NULL, 0, NULL},
    },
    {
        {"ex_pi", "pi", 3.14159265358979323846},
        {"ex_version", "plugin version", 1},
        {NULL, NULL, 0},
    },
};

const beamctl_plugin* beamctl_plugin_get(void) { return &plugin; }
