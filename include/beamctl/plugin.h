/* beamctl plugin C ABI.
 *
 * A plugin is a shared library (built with any C or C++ compiler) that exports one function,
 * `beamctl_plugin_get`, returning a pointer to a static `beamctl_plugin` description. beamctl
 * loads it with dlopen (`plugins:` in the IOC file, or the `plc` commands), checks
 * `abi_version`, calls `construct(config)` once, `rt_enter()` before the RT cycle starts,
 * `realtime(error)` once per cycle on the RT thread (after the general PLCs), `rt_exit()` when
 * the cycle stops and `destruct()` at unload. Its functions and constants are callable from PLC
 * code by name (a PLC binds them when its text uses them), as ECMC plugins are.
 *
 * Rules for code that runs in the cycle (`realtime` and the functions): no blocking, no
 * allocation, no locks held for long; return quickly. Threading: construct/destruct/rt_enter/
 * rt_exit on a non-RT thread; realtime and the functions on the RT thread only.
 */
#ifndef BEAMCTL_PLUGIN_H
#define BEAMCTL_PLUGIN_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Bumped whenever the layout below changes; a plugin built for another version is refused. */
#define BEAMCTL_PLUGIN_ABI_VERSION 1u
#define BEAMCTL_PLUGIN_MAX_FUNCTIONS 64
#define BEAMCTL_PLUGIN_MAX_CONSTANTS 64
#define BEAMCTL_PLUGIN_MAX_ARGS 6

/* A function callable from PLC code: `nargs` (0..6) doubles in `args`, returns a double. */
typedef struct beamctl_plugin_function {
    const char* name; /* PLC name, e.g. "my_gain"; NULL ends the list */
    const char* desc;
    int nargs;
    double (*fn)(const double* args);
} beamctl_plugin_function;

typedef struct beamctl_plugin_constant {
    const char* name; /* NULL ends the list */
    const char* desc;
    double value;
} beamctl_plugin_constant;

typedef struct beamctl_plugin {
    uint32_t abi_version;           /* BEAMCTL_PLUGIN_ABI_VERSION */
    const char* name;               /* short name, e.g. "example" */
    const char* description;
    const char* option_description; /* what `config` may contain */
    uint32_t version;               /* the plugin's own version */
    int (*construct)(const char* config); /* 0 = OK; may be NULL */
    void (*destruct)(void);               /* may be NULL */
    int (*rt_enter)(void);                /* 0 = OK; may be NULL */
    int (*rt_exit)(void);                 /* may be NULL */
    int (*realtime)(int error_code);      /* each cycle; error_code: 0 or the IOC's; may be NULL */
    beamctl_plugin_function functions[BEAMCTL_PLUGIN_MAX_FUNCTIONS];
    beamctl_plugin_constant constants[BEAMCTL_PLUGIN_MAX_CONSTANTS];
} beamctl_plugin;

/* The one symbol a plugin exports. */
typedef const beamctl_plugin* (*beamctl_plugin_get_fn)(void);
#define BEAMCTL_PLUGIN_ENTRY "beamctl_plugin_get"

#ifdef __cplusplus
}
#endif

#endif /* BEAMCTL_PLUGIN_H */
