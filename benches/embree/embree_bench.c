/* Closest-hit throughput of Embree 3 (rtcIntersect1 and rtcIntersect8) on a
 * triangle mesh, for comparison with rothray's MeshData::closest_hit.
 *
 * usage: embree_bench MESH RAYS THREADS REPEATS [OUT_T]
 *   MESH  binary, little endian: u32 nverts, u32 ntris, f32 xyz * nverts, u32 abc * ntris
 *   RAYS  binary, little endian: u32 nrays, then per ray f32 ox oy oz dx dy dz tmin tmax
 *         (packets are 8 consecutive rays; the writer orders camera rays in 4x2 blocks)
 *   OUT_T optional: f32 t per ray from rtcIntersect1 (+inf for a miss)
 *
 * Prints one line per method: median / min seconds over REPEATS runs and Mrays/s.
 * Work is split into chunks of 1024 rays taken from an atomic counter, on
 * THREADS pthreads, the same scheme the Rust side uses with rayon. */
#include <embree3/rtcore.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <time.h>

#define CHUNK 1024

static float *rays; /* 8 floats per ray */
static uint32_t nrays;
static float *out_t;
static RTCScene scene;
static atomic_uint next_chunk;
static atomic_ulong hit_count;

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void *read_file(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) { perror(path); exit(1); }
    fseek(f, 0, SEEK_END);
    *len = ftell(f);
    fseek(f, 0, SEEK_SET);
    void *p = malloc(*len);
    if (fread(p, 1, *len, f) != *len) { perror(path); exit(1); }
    fclose(f);
    return p;
}

static void *worker1(void *arg) {
    (void)arg;
    unsigned long hits = 0;
    for (;;) {
        uint32_t c = atomic_fetch_add(&next_chunk, 1);
        uint32_t b = c * CHUNK;
        if (b >= nrays) break;
        uint32_t e = b + CHUNK < nrays ? b + CHUNK : nrays;
        for (uint32_t i = b; i < e; i++) {
            const float *r = rays + 8 * (size_t)i;
            struct RTCIntersectContext ctx;
            rtcInitIntersectContext(&ctx);
            struct RTCRayHit rh;
            rh.ray.org_x = r[0]; rh.ray.org_y = r[1]; rh.ray.org_z = r[2];
            rh.ray.dir_x = r[3]; rh.ray.dir_y = r[4]; rh.ray.dir_z = r[5];
            rh.ray.tnear = r[6]; rh.ray.tfar = r[7];
            rh.ray.time = 0; rh.ray.mask = -1; rh.ray.id = i; rh.ray.flags = 0;
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(scene, &ctx, &rh);
            int hit = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
            hits += hit;
            if (out_t) out_t[i] = hit ? rh.ray.tfar : INFINITY;
        }
    }
    atomic_fetch_add(&hit_count, hits);
    return NULL;
}

static void *worker8(void *arg) {
    (void)arg;
    unsigned long hits = 0;
    struct RTCRayHit8 rh __attribute__((aligned(32)));
    int valid[8] __attribute__((aligned(32)));
    for (;;) {
        uint32_t c = atomic_fetch_add(&next_chunk, 1);
        uint32_t b = c * CHUNK;
        if (b >= nrays) break;
        uint32_t e = b + CHUNK < nrays ? b + CHUNK : nrays;
        for (uint32_t p = b; p < e; p += 8) {
            struct RTCIntersectContext ctx;
            rtcInitIntersectContext(&ctx);
            ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
            for (int k = 0; k < 8; k++) {
                uint32_t i = p + k;
                valid[k] = i < e ? -1 : 0;
                const float *r = rays + 8 * (size_t)(i < e ? i : p);
                rh.ray.org_x[k] = r[0]; rh.ray.org_y[k] = r[1]; rh.ray.org_z[k] = r[2];
                rh.ray.dir_x[k] = r[3]; rh.ray.dir_y[k] = r[4]; rh.ray.dir_z[k] = r[5];
                rh.ray.tnear[k] = r[6]; rh.ray.tfar[k] = r[7];
                rh.ray.time[k] = 0; rh.ray.mask[k] = -1; rh.ray.id[k] = i; rh.ray.flags[k] = 0;
                rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
                rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
            }
            rtcIntersect8(valid, scene, &ctx, &rh);
            for (int k = 0; k < 8; k++) {
                if (!valid[k]) continue;
                hits += rh.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;
            }
        }
    }
    atomic_fetch_add(&hit_count, hits);
    return NULL;
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static void run(const char *name, void *(*fn)(void *), int threads, int repeats) {
    double *times = malloc(sizeof(double) * repeats);
    pthread_t th[64];
    unsigned long hits = 0;
    /* one warm-up run, then the timed repeats */
    for (int r = -1; r < repeats; r++) {
        atomic_store(&next_chunk, 0);
        atomic_store(&hit_count, 0);
        double t0 = now();
        for (int k = 0; k < threads; k++) pthread_create(&th[k], NULL, fn, NULL);
        for (int k = 0; k < threads; k++) pthread_join(th[k], NULL);
        double t1 = now();
        if (r >= 0) times[r] = t1 - t0;
        hits = atomic_load(&hit_count);
    }
    qsort(times, repeats, sizeof(double), cmp_double);
    double med = times[repeats / 2];
    printf("embree %-14s threads %d rays %u hits %lu median %.4f s min %.4f s  %.2f Mrays/s\n", name, threads, nrays, hits,
           med, times[0], nrays / med / 1e6);
    fflush(stdout);
    free(times);
}

int main(int argc, char **argv) {
    if (argc < 5) {
        fprintf(stderr, "usage: %s MESH RAYS THREADS REPEATS [OUT_T]\n", argv[0]);
        return 2;
    }
    int threads = atoi(argv[3]);
    int repeats = atoi(argv[4]);
    if (threads < 1 || threads > 64 || repeats < 1) { fprintf(stderr, "bad THREADS or REPEATS\n"); return 2; }

    size_t len;
    uint32_t *mesh = read_file(argv[1], &len);
    uint32_t nv = mesh[0], nt = mesh[1];
    const float *pos = (const float *)(mesh + 2);
    const uint32_t *idx = mesh + 2 + 3 * (size_t)nv;
    if (len != 8 + 12 * (size_t)nv + 12 * (size_t)nt) { fprintf(stderr, "bad mesh file\n"); return 1; }

    uint32_t *rf = read_file(argv[2], &len);
    nrays = rf[0];
    rays = (float *)(rf + 1);
    if (len != 4 + 32 * (size_t)nrays) { fprintf(stderr, "bad ray file\n"); return 1; }

    /* threads=N: Embree's own build threads; tracing uses our pthreads */
    char cfg[64];
    snprintf(cfg, sizeof cfg, "threads=%d", threads);
    RTCDevice dev = rtcNewDevice(cfg);
    if (!dev) { fprintf(stderr, "rtcNewDevice failed: %d\n", rtcGetDeviceError(NULL)); return 1; }
    scene = rtcNewScene(dev);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, nv);
    memcpy(vb, pos, 12 * (size_t)nv);
    uint32_t *ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, nt);
    memcpy(ib, idx, 12 * (size_t)nt);
    rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_HIGH);
    rtcCommitGeometry(g);
    rtcAttachGeometry(scene, g);
    rtcReleaseGeometry(g);
    double t0 = now();
    rtcCommitScene(scene);
    double tb = now() - t0;
    printf("embree %s: %u vertices, %u triangles, build (quality high) %.3f s\n", rtcGetDeviceProperty(dev, RTC_DEVICE_PROPERTY_VERSION) ? RTC_VERSION_STRING : "?", nv, nt, tb);

    if (argc > 5) out_t = malloc(4 * (size_t)nrays);
    run("rtcIntersect1", worker1, threads, repeats);
    if (out_t) {
        FILE *f = fopen(argv[5], "wb");
        fwrite(out_t, 4, nrays, f);
        fclose(f);
        free(out_t);
        out_t = NULL;
    }
    run("rtcIntersect8", worker8, threads, repeats);

    rtcReleaseScene(scene);
    rtcReleaseDevice(dev);
    return 0;
}
