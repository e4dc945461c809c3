/* beamctl record routines C ABI: the subroutines of `sub` and `aSub` records.
 *
 * EPICS IOCs find a sub/aSub record's INAM (init) and SNAM (process) routines by name in the
 * IOC's registry (registryFunctionAdd, from a .dbd `function(name)` line). beamctl finds them in
 * shared libraries loaded with `dlload path.so` in a startup script (or `beamctl softioc -P
 * path.so`): such a library exports `beamctl_record_routines_get`, returning a static table of
 * named routines. A routine sees the record's fields through the struct below, as an EPICS
 * routine sees `subRecord`/`aSubRecord`:
 *
 *   sub:  A..L (inputs, read from INPA..INPL before the routine runs) and VAL. A return value
 *         < 0 raises a SOFT alarm of severity BRSV (VAL keeps whatever the routine left there,
 *         UDF is not cleared); >= 0 clears UDF unless VAL is NaN. Then VAL's limit alarms,
 *         deadbands and monitors run as subRecord's.
 *   aSub: inputs A..U are arrays a[0..20] of fta[i] (a menuFtype, BEAMCTL_FT_*) with room for
 *         noa[i] elements, nea[i] of them read from INPA..INPU; outputs vala[0..20] of ftva[i],
 *         room nova[i], the routine sets neva[i] (how many OUTA..OUTU write). The return value
 *         becomes VAL; nonzero skips the output links, < 0 also raises a SOFT alarm of severity
 *         BRSV.
 *
 * The same routine type serves INAM (called once at init) and SNAM. Routines run on the
 * database thread while the record is being processed: they must return quickly, must not
 * block, and must not keep the pointers they are given beyond the call (except `user`, which is
 * theirs: beamctl never touches it). Asynchronous completion (EPICS: setting PACT) is not
 * supported. A library may also be a PLC plugin (include/beamctl/plugin.h): the two entries are
 * independent.
 */
#ifndef BEAMCTL_RECORD_ROUTINES_H
#define BEAMCTL_RECORD_ROUTINES_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Bumped whenever the layout below changes; a library built for another version is refused. */
#define BEAMCTL_RECORD_ROUTINES_ABI_VERSION 1u
#define BEAMCTL_ASUB_ARGS 21 /* A..U, VALA..VALU: index 0 is A (VALA), 20 is U (VALU) */

/* menuFtype: the element types of aSub's arrays (fta, ftva). */
enum beamctl_ftype {
    BEAMCTL_FT_STRING = 0, /* char[40] elements */
    BEAMCTL_FT_CHAR = 1,   /* int8_t */
    BEAMCTL_FT_UCHAR = 2,  /* uint8_t */
    BEAMCTL_FT_SHORT = 3,  /* int16_t */
    BEAMCTL_FT_USHORT = 4, /* uint16_t */
    BEAMCTL_FT_LONG = 5,   /* int32_t */
    BEAMCTL_FT_ULONG = 6,  /* uint32_t */
    BEAMCTL_FT_INT64 = 7,  /* int64_t */
    BEAMCTL_FT_UINT64 = 8, /* uint64_t */
    BEAMCTL_FT_FLOAT = 9,  /* float */
    BEAMCTL_FT_DOUBLE = 10 /* double */
};

/* What a sub record's routine sees. */
typedef struct beamctl_sub {
    const char* name; /* the record's name */
    void* user;       /* the routines' own pointer (EPICS: DPVT); NULL at first */
    double val;       /* VAL */
    double a, b, c, d, e, f, g, h, i, j, k, l; /* A..L */
} beamctl_sub;

/* What an aSub record's routine sees. */
typedef struct beamctl_asub {
    const char* name;
    void* user;
    int32_t val; /* VAL: the last return value */
    void* a[BEAMCTL_ASUB_ARGS];     /* A..U: input arrays */
    uint16_t fta[BEAMCTL_ASUB_ARGS];  /* FTA..FTU */
    uint32_t noa[BEAMCTL_ASUB_ARGS];  /* NOA..NOU: capacity */
    uint32_t nea[BEAMCTL_ASUB_ARGS];  /* NEA..NEU: elements read */
    void* vala[BEAMCTL_ASUB_ARGS];    /* VALA..VALU: output arrays */
    uint16_t ftva[BEAMCTL_ASUB_ARGS]; /* FTVA..FTVU */
    uint32_t nova[BEAMCTL_ASUB_ARGS]; /* NOVA..NOVU: capacity */
    uint32_t neva[BEAMCTL_ASUB_ARGS]; /* NEVA..NEVU: elements to write (set by the routine) */
} beamctl_asub;

typedef long (*beamctl_sub_routine)(beamctl_sub* rec);
typedef long (*beamctl_asub_routine)(beamctl_asub* rec);

/* One named routine: exactly one of `sub` and `asub` is set. */
typedef struct beamctl_record_routine {
    const char* name; /* the INAM/SNAM it answers to; NULL ends the table */
    beamctl_sub_routine sub;
    beamctl_asub_routine asub;
} beamctl_record_routine;

typedef struct beamctl_record_routines {
    uint32_t abi_version; /* BEAMCTL_RECORD_ROUTINES_ABI_VERSION */
    const char* name;     /* the library's short name, for messages */
    const beamctl_record_routine* routines;
} beamctl_record_routines;

/* The one symbol a routine library exports. */
typedef const beamctl_record_routines* (*beamctl_record_routines_get_fn)(void);
#define BEAMCTL_RECORD_ROUTINES_ENTRY "beamctl_record_routines_get"

#ifdef __cplusplus
}
#endif

#endif /* BEAMCTL_RECORD_ROUTINES_H */
