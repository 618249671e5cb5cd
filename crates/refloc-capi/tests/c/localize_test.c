/* C test of the refloc C ABI (crates/refloc-capi), linked against the
 * staticlib by scripts/capi-test.sh.
 *
 *   localize_test MAP.refdb SCAN.txt
 *
 * SCAN.txt (written by `refloc-scangen capi`):
 *   # comment lines
 *   truth X Y THETA
 *   scan ANGLE_MIN ANGLE_INCREMENT RANGE_MIN RANGE_MAX N
 *   N ranges, whitespace separated ("inf" = no return)
 *
 * Loads the map into a 16-byte aligned buffer, opens and verifies it, sizes
 * the scratch, localizes the scan as ranges and as points, checks the pose
 * against the truth (0.3 m, 5 deg, accepted), and checks the error paths.
 * All memory is this program's own: the library allocates nothing. Built
 * with -DREFLOC_TRACK_ALLOC and the linker's --wrap for the allocation
 * functions (as scripts/capi-test.sh does), the test proves it: every
 * allocation call from the Rust library lands in a counting wrapper, while
 * this file allocates through the real functions.
 * Prints "N passed, M failed"; exits 0 when nothing failed. */

#define _POSIX_C_SOURCE 200112L /* posix_memalign */

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "refloc.h"

#define MAX_POS_ERR 0.3
#define MAX_THETA_ERR (5.0 * 3.14159265358979 / 180.0)

static int passed, failed;

#ifdef REFLOC_TRACK_ALLOC
/* Link with -Wl,--wrap=malloc,--wrap=calloc,--wrap=realloc,
 * --wrap=posix_memalign,--wrap=aligned_alloc,--wrap=memalign. */
static int lib_allocs;
void *__real_malloc(size_t n);
void *__real_calloc(size_t n, size_t size);
void *__real_realloc(void *p, size_t n);
int __real_posix_memalign(void **p, size_t align, size_t n);
void *__real_aligned_alloc(size_t align, size_t n);
void *__real_memalign(size_t align, size_t n);
void *__wrap_malloc(size_t n) { lib_allocs++; return __real_malloc(n); }
void *__wrap_calloc(size_t n, size_t size) { lib_allocs++; return __real_calloc(n, size); }
void *__wrap_realloc(void *p, size_t n) { lib_allocs++; return __real_realloc(p, n); }
int __wrap_posix_memalign(void **p, size_t align, size_t n) { lib_allocs++; return __real_posix_memalign(p, align, n); }
void *__wrap_aligned_alloc(size_t align, size_t n) { lib_allocs++; return __real_aligned_alloc(align, n); }
void *__wrap_memalign(size_t align, size_t n) { lib_allocs++; return __real_memalign(align, n); }
#define own_malloc __real_malloc
#define own_posix_memalign __real_posix_memalign
#else
#define own_malloc malloc
#define own_posix_memalign posix_memalign
#endif

static void check(int ok, const char *what) {
    if (ok) {
        passed++;
        printf("ok   %s\n", what);
    } else {
        failed++;
        printf("FAIL %s\n", what);
    }
}

static void check_status(refloc_status got, refloc_status want, const char *what) {
    char line[256];
    snprintf(line, sizeof line, "%s: %d (%s)", what, (int)got, refloc_strerror(got));
    if (got != want) {
        failed++;
        printf("FAIL %s, expected %d (%s)\n", line, (int)want, refloc_strerror(want));
    } else {
        passed++;
        printf("ok   %s\n", line);
    }
}

static double wrap(double a) {
    while (a > 3.14159265358979) a -= 2.0 * 3.14159265358979;
    while (a <= -3.14159265358979) a += 2.0 * 3.14159265358979;
    return a;
}

/* Reads a whole file into 16-byte aligned memory (REFLOC_DB_BYTES_ALIGN). */
static uint8_t *read_file(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        perror(path);
        return NULL;
    }
    if (fseek(f, 0, SEEK_END) != 0) {
        fclose(f);
        return NULL;
    }
    long n = ftell(f);
    rewind(f);
    void *buf = NULL;
    if (n < 0 || own_posix_memalign(&buf, REFLOC_DB_BYTES_ALIGN, (size_t)n) != 0) {
        fclose(f);
        return NULL;
    }
    if (fread(buf, 1, (size_t)n, f) != (size_t)n) {
        perror(path);
        free(buf);
        fclose(f);
        return NULL;
    }
    fclose(f);
    *len = (size_t)n;
    return buf;
}

struct scan {
    double truth[3];
    float angle_min, angle_increment, range_min, range_max;
    size_t n;
    float *ranges;
};

static int read_scan(const char *path, struct scan *s) {
    FILE *f = fopen(path, "r");
    if (!f) {
        perror(path);
        return -1;
    }
    char line[512];
    int have_truth = 0, have_scan = 0;
    while (!(have_truth && have_scan) && fgets(line, sizeof line, f)) {
        if (line[0] == '#') continue;
        if (sscanf(line, "truth %lf %lf %lf", &s->truth[0], &s->truth[1], &s->truth[2]) == 3) {
            have_truth = 1;
        } else if (sscanf(line, "scan %f %f %f %f %zu", &s->angle_min, &s->angle_increment,
                          &s->range_min, &s->range_max, &s->n) == 5) {
            have_scan = 1;
        }
    }
    if (!have_truth || !have_scan || s->n == 0 || s->n > 100000) {
        fprintf(stderr, "%s: missing or bad 'truth'/'scan' lines\n", path);
        fclose(f);
        return -1;
    }
    s->ranges = own_malloc(s->n * sizeof(float));
    if (!s->ranges) {
        fclose(f);
        return -1;
    }
    for (size_t k = 0; k < s->n; k++) {
        char word[64];
        if (fscanf(f, "%63s", word) != 1) {
            fprintf(stderr, "%s: %zu ranges, expected %zu\n", path, k, s->n);
            fclose(f);
            return -1;
        }
        s->ranges[k] = strtof(word, NULL); /* "inf" parses as infinity */
    }
    fclose(f);
    return 0;
}

static void check_pose(const refloc_result *r, const double truth[3], const char *what) {
    double dp = hypot(r->x - truth[0], r->y - truth[1]);
    double dt = fabs(wrap(r->theta - truth[2]));
    char line[256];
    snprintf(line, sizeof line,
             "%s: pose (%.3f, %.3f, %.4f) truth (%.3f, %.3f, %.4f) error %.3f m %.2f deg, "
             "site %u, M %.1f > %.1f %s",
             what, r->x, r->y, r->theta, truth[0], truth[1], truth[2], dp, dt * 180.0 / 3.14159265358979,
             r->site, r->vicinity, r->vicinity_threshold, r->accepted ? "accepted" : "rejected");
    check(r->accepted == 1 && dp < MAX_POS_ERR && dt < MAX_THETA_ERR, line);
    snprintf(line, sizeof line, "%s: confidence %.4f, %u hypotheses, first at (%.3f, %.3f)", what,
             r->confidence, r->hypothesis_count, r->hypotheses[0].x, r->hypotheses[0].y);
    check(r->confidence > 0.5f && r->confidence <= 1.0f && r->hypothesis_count >= 1 &&
              r->hypothesis_count <= 5 && r->hypotheses[0].x == r->x && r->hypotheses[0].y == r->y &&
              r->hypotheses[0].confidence == r->confidence,
          line);
    snprintf(line, sizeof line, "%s: covariance diagonal %.3g m^2 %.3g m^2 %.3g rad^2", what,
             r->covariance[0], r->covariance[4], r->covariance[8]);
    check(r->covariance[0] > 0.0f && r->covariance[4] > 0.0f && r->covariance[8] > 0.0f &&
              r->covariance[1] == r->covariance[3] && r->covariance[0] < 1.0f && r->covariance[4] < 1.0f,
          line);
}

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: %s MAP.refdb SCAN.txt\n", argv[0]);
        return 2;
    }
    size_t len = 0;
    uint8_t *bytes = read_file(argv[1], &len);
    struct scan s;
    memset(&s, 0, sizeof s);
    if (!bytes || read_scan(argv[2], &s) != 0) return 2;

#ifdef REFLOC_TRACK_ALLOC
    {
        /* Through the wrapper (volatile: the call must not be optimized away). */
        void *volatile probe = malloc(1);
        check(lib_allocs == 1, "allocation tracking is active");
        free(probe);
        lib_allocs = 0;
    }
#endif

    /* Open, verify, describe. The handle lives on the stack. */
    refloc_db db;
    check_status(refloc_db_open(bytes, len, &db), REFLOC_OK, "open");
    check_status(refloc_db_verify(&db), REFLOC_OK, "verify");
    refloc_db_info info;
    check_status(refloc_db_get_info(&db, &info), REFLOC_OK, "info");
    printf("     map %ux%u cells at %.3f m, %u sites, %u reference beams, %llu bytes\n", info.width,
           info.height, info.resolution, info.sites, info.reference_beams,
           (unsigned long long)info.file_bytes);
    check(info.file_bytes == len && info.sites > 0, "info matches the file");

    /* Scratch for this scan. */
    size_t need = refloc_scratch_size(&db, s.n);
    printf("     scratch for %zu beams: %zu bytes\n", s.n, need);
    check(need > 0, "scratch size");
    uint8_t *scratch = own_malloc(need + 1);
    if (!scratch) return 2;

    /* Localize as ranges; the scratch deliberately starts on an odd address. */
    refloc_result r;
    check_status(refloc_localize_ranges(&db, s.angle_min, s.angle_increment, s.range_min,
                                        s.range_max, s.ranges, s.n, scratch + 1, need, &r),
                 REFLOC_OK, "localize ranges");
    check_pose(&r, s.truth, "ranges");
    check(r.valid_points > 0 && r.candidates > 0 && r.reserved[0] == 0, "result fields");

    /* With a prior around the truth (5 m, +-30 deg): the same pose; a bad prior is refused. */
    refloc_prior prior = {(float)s.truth[0] + 1.0f, (float)s.truth[1], 5.0f, (float)s.truth[2],
                          0.5236f};
    refloc_result rpr;
    check_status(refloc_localize_ranges_prior(&db, s.angle_min, s.angle_increment, s.range_min,
                                              s.range_max, s.ranges, s.n, &prior, scratch, need,
                                              &rpr),
                 REFLOC_OK, "localize ranges with a prior");
    check_pose(&rpr, s.truth, "ranges with a prior");
    check_status(refloc_localize_ranges_prior(&db, s.angle_min, s.angle_increment, s.range_min,
                                              s.range_max, s.ranges, s.n, NULL, scratch, need,
                                              &rpr),
                 REFLOC_OK, "NULL prior");
    check(rpr.x == r.x && rpr.y == r.y && rpr.theta == r.theta, "NULL prior = no prior");
    prior.radius = -1.0f;
    check_status(refloc_localize_ranges_prior(&db, s.angle_min, s.angle_increment, s.range_min,
                                              s.range_max, s.ranges, s.n, &prior, scratch, need,
                                              &rpr),
                 REFLOC_ERR_BAD_PRIOR, "negative prior radius");

    /* A polygon prior: a square around the truth finds it; a triangle away
     * from every site ranks none; bad polygons are typed errors. */
    float tx = (float)s.truth[0], ty = (float)s.truth[1];
    float square[8] = {tx - 2.0f, ty - 2.0f, tx + 3.0f, ty - 2.0f,
                       tx + 3.0f, ty + 2.0f, tx - 2.0f, ty + 2.0f};
    refloc_prior facing = {0.0f, 0.0f, INFINITY, (float)s.truth[2], 0.5236f};
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, square, 4, &facing,
                                                scratch, need, &rpr),
                 REFLOC_OK, "localize ranges in a polygon");
    check_pose(&rpr, s.truth, "ranges in a polygon");
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, square, 4, NULL,
                                                scratch, need, &rpr),
                 REFLOC_OK, "polygon with no heading window");
    check_pose(&rpr, s.truth, "ranges in a polygon, any heading");
    float far[6] = {tx + 500.0f, ty + 500.0f, tx + 501.0f, ty + 500.0f, tx + 500.0f, ty + 501.0f};
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, far, 3, NULL, scratch,
                                                need, &rpr),
                 REFLOC_ERR_NO_MATCH, "polygon away from every site");
    facing.radius = 5.0f;
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, square, 4, &facing,
                                                scratch, need, &rpr),
                 REFLOC_ERR_BAD_PRIOR, "a circle and a polygon at once");
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, square, 2, NULL,
                                                scratch, need, &rpr),
                 REFLOC_ERR_BAD_POLYGON, "2-vertex polygon");
    check(rpr.accepted == 0 && rpr.x == 0.0f, "result zeroed on a bad polygon");
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, NULL, 0, NULL, scratch,
                                                need, &rpr),
                 REFLOC_ERR_BAD_POLYGON, "empty polygon");
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, NULL, 4, NULL, scratch,
                                                need, &rpr),
                 REFLOC_ERR_NULL, "NULL polygon");
    float many[2 * (REFLOC_MAX_POLYGON_VERTICES + 1)];
    for (int k = 0; k <= REFLOC_MAX_POLYGON_VERTICES; k++) {
        float a = 6.2831853f * (float)k / (float)(REFLOC_MAX_POLYGON_VERTICES + 1);
        many[2 * k] = tx + 3.0f * cosf(a);
        many[2 * k + 1] = ty + 3.0f * sinf(a);
    }
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, many,
                                                REFLOC_MAX_POLYGON_VERTICES, NULL, scratch, need,
                                                &rpr),
                 REFLOC_OK, "polygon of REFLOC_MAX_POLYGON_VERTICES vertices");
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, many,
                                                REFLOC_MAX_POLYGON_VERTICES + 1, NULL, scratch,
                                                need, &rpr),
                 REFLOC_ERR_BAD_POLYGON, "polygon of too many vertices");
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, many, SIZE_MAX, NULL,
                                                scratch, need, &rpr),
                 REFLOC_ERR_BAD_POLYGON, "polygon of SIZE_MAX vertices");
    square[5] = NAN;
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, square, 4, NULL,
                                                scratch, need, &rpr),
                 REFLOC_ERR_BAD_POLYGON, "NaN vertex");
    float flat[6] = {1.0f, 1.0f, 2.0f, 2.0f, 3.0f, 3.0f};
    check_status(refloc_localize_ranges_polygon(&db, s.angle_min, s.angle_increment, s.range_min,
                                                s.range_max, s.ranges, s.n, flat, 3, NULL, scratch,
                                                need, &rpr),
                 REFLOC_ERR_BAD_POLYGON, "vertices on one line");

    /* The same scan as points (x, y pairs; no return = NaN). */
    float *pts = own_malloc(2 * s.n * sizeof(float));
    if (!pts) return 2;
    for (size_t k = 0; k < s.n; k++) {
        float a = s.angle_min + (float)k * s.angle_increment;
        float d = s.ranges[k];
        pts[2 * k] = isfinite(d) ? d * cosf(a) : NAN;
        pts[2 * k + 1] = isfinite(d) ? d * sinf(a) : NAN;
    }
    refloc_result rp;
    check_status(refloc_localize_points(&db, pts, s.n, s.range_max, scratch, need, &rp), REFLOC_OK,
                 "localize points");
    check_pose(&rp, s.truth, "points");

    /* Error paths. */
    check_status(refloc_localize_ranges(&db, s.angle_min, s.angle_increment, s.range_min,
                                        s.range_max, s.ranges, s.n, scratch, 16, &r),
                 REFLOC_ERR_SCRATCH_TOO_SMALL, "16-byte scratch");
    check(r.accepted == 0 && r.x == 0.0f, "result zeroed on error");
    refloc_status st = refloc_localize_ranges(&db, s.angle_min, s.angle_increment, s.range_min,
                                              s.range_max, s.ranges, s.n, scratch, need - 1, &r);
    check(st == REFLOC_ERR_TOO_MANY_BEAMS || st == REFLOC_ERR_SCRATCH_TOO_SMALL,
          "scratch one byte short is refused");
    check_status(refloc_localize_ranges(&db, s.angle_min, s.angle_increment, s.range_min,
                                        s.range_max, NULL, s.n, scratch, need, &r),
                 REFLOC_ERR_NULL, "NULL ranges");
    check_status(refloc_localize_ranges(&db, s.angle_min, s.angle_increment, s.range_min,
                                        s.range_max, s.ranges, s.n, scratch, need, NULL),
                 REFLOC_ERR_NULL, "NULL result");
    check_status(refloc_localize_ranges(&db, s.angle_min, 0.0f, s.range_min, s.range_max,
                                        s.ranges, s.n, scratch, need, &r),
                 REFLOC_ERR_BAD_SCAN, "zero angle increment");
    check_status(refloc_localize_ranges(&db, s.angle_min, s.angle_increment, s.range_min,
                                        s.range_max, s.ranges, 5, scratch, need, &r),
                 REFLOC_ERR_NOT_ENOUGH_POINTS, "5-beam scan");
    check_status(refloc_localize_ranges(&db, s.angle_min, s.angle_increment, s.range_min,
                                        s.range_max, (const float *)((const char *)s.ranges + 1),
                                        s.n - 1, scratch, need, &r),
                 REFLOC_ERR_ALIGNMENT, "misaligned ranges");
    check(refloc_scratch_size(NULL, 100) == 0, "scratch size of NULL handle is 0");

    /* Bad databases. */
    refloc_db bad;
    check_status(refloc_db_open(bytes, len - 1, &bad), REFLOC_ERR_DB_TRUNCATED, "truncated map");
    check_status(refloc_db_verify(&bad), REFLOC_ERR_BAD_HANDLE, "failed open leaves the handle closed");
    check_status(refloc_db_open((const uint8_t *)"not a map at all, not a map at all", 34, &bad),
                 REFLOC_ERR_DB_NOT_REFDB, "not a map");
    check_status(refloc_db_open(NULL, len, &bad), REFLOC_ERR_NULL, "NULL bytes");
    check_status(refloc_db_open(bytes, len, NULL), REFLOC_ERR_NULL, "NULL handle");
    uint8_t *shifted = NULL;
    {
        void *p = NULL;
        if (own_posix_memalign(&p, REFLOC_DB_BYTES_ALIGN, len + 4) != 0) return 2;
        shifted = p;
        memcpy(shifted + 1, bytes, len); /* odd address */
        check_status(refloc_db_open(shifted + 1, len, &bad), REFLOC_ERR_DB_ALIGNMENT,
                     "map at an odd address");
    }
    {
        uint8_t *copy = NULL;
        void *p = NULL;
        if (own_posix_memalign(&p, REFLOC_DB_BYTES_ALIGN, len) != 0) return 2;
        copy = p;
        memcpy(copy, bytes, len);
        copy[len / 2] ^= 0x5A; /* in the middle of the section data */
        refloc_status o = refloc_db_open(copy, len, &bad);
        refloc_status v = o == REFLOC_OK ? refloc_db_verify(&bad) : o;
        printf("     corrupted byte: open %d, verify %d (%s)\n", (int)o, (int)v, refloc_strerror(v));
        check(v != REFLOC_OK, "a corrupted byte is caught by open or verify");
        free(copy);
    }

    /* Close: the handle is refused afterwards. */
    refloc_db_close(&db);
    check_status(refloc_db_verify(&db), REFLOC_ERR_BAD_HANDLE, "closed handle");
    check(refloc_strerror(12345) != NULL && strlen(refloc_strerror(-1)) > 0, "strerror of unknown codes");

#ifdef REFLOC_TRACK_ALLOC
    {
        char line[64];
        snprintf(line, sizeof line, "the library made %d allocation calls", lib_allocs);
        check(lib_allocs == 0, line);
    }
#endif
    free(shifted);
    free(pts);
    free(scratch);
    free(s.ranges);
    free(bytes);
    printf("%d passed, %d failed\n", passed, failed);
    return failed == 0 ? 0 : 1;
}
