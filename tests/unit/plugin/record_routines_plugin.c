/* sub/aSub routines for the record tests (include/beamctl/record_routines.h): loaded with
 * RecordRoutines::load in the unit tests and with `dlload` by the softioc system test. */
#include "beamctl/record_routines.h"

#include <stddef.h>

static long sub_sum(beamctl_sub* r) { /* VAL = A + B + ... + L */
    r->val = r->a + r->b + r->c + r->d + r->e + r->f + r->g + r->h + r->i + r->j + r->k + r->l;
    return 0;
}

static long sub_fail(beamctl_sub* r) { /* an error: VAL as left, SOFT alarm of BRSV */
    r->val = -1;
    return -1;
}

static int init_calls;
static long sub_init(beamctl_sub* r) { /* INAM: counts its calls in `user`, sets VAL */
    ++init_calls;
    r->user = &init_calls;
    r->val = 7;
    return 0;
}

static long sub_count(beamctl_sub* r) { /* VAL = the INAM calls seen through `user` */
    r->val = r->user ? *(int*)r->user : -1;
    return 0;
}

/* VALA = A * B[0] element-wise (NEVA = NEA), VALB[0] = the sum of A (VALB a LONG). */
static long asub_scale(beamctl_asub* r) {
    const double* a = (const double*)r->a[0];
    double k = *(const double*)r->a[1];
    double* out = (double*)r->vala[0];
    double sum = 0;
    uint32_t n = r->nea[0] < r->nova[0] ? r->nea[0] : r->nova[0];
    for (uint32_t i = 0; i < n; ++i) {
        out[i] = a[i] * k;
        sum += a[i];
    }
    r->neva[0] = n;
    if (r->ftva[1] == BEAMCTL_FT_LONG) *(int32_t*)r->vala[1] = (int32_t)sum;
    return 0;
}

static long asub_fail(beamctl_asub* r) { (void)r; return -2; }
static long asub_skip(beamctl_asub* r) { /* positive: outputs skipped, no alarm */
    *(double*)r->vala[0] = 123;
    return 1;
}

static const beamctl_record_routine routines[] = {
    {"sub_sum", sub_sum, NULL},     {"sub_fail", sub_fail, NULL},   {"sub_init", sub_init, NULL},
    {"sub_count", sub_count, NULL}, {"asub_scale", NULL, asub_scale}, {"asub_fail", NULL, asub_fail},
    {"asub_skip", NULL, asub_skip}, {NULL, NULL, NULL},
};

static const beamctl_record_routines table = {BEAMCTL_RECORD_ROUTINES_ABI_VERSION, "test_routines", routines};

const beamctl_record_routines* beamctl_record_routines_get(void) { return &table; }
