// The GPU tracer's kernels, written once for two compilers: NVRTC makes the PTX the driver runs
// (scripts/gpu_ptx.sh, checked in as kernels.ptx), and g++ builds the same source for the host
// (nodes/build.rs, feature `cuda`) so that CI without a GPU can check every hit against the Rust
// tracer. `CUDA_CALLABLE` marks what both compile (NVIDIA Warp's style, warp/native/bvh.h).
//
// Bit-exactness with `geom::wide_bvh` (the CPU's closest hit) rests on:
// - the same IEEE operations in the same order: no contraction into fused multiply-adds
//   (NVRTC --fmad=false, g++ -ffp-contract=off), IEEE division and square root
//   (-prec-div=true -prec-sqrt=true), no flush of subnormals;
// - min and max as the CPU's compare-selects (`a < b ? a : b`, the second operand unless the
//   first is smaller: `_mm256_min_ps`'s rule), never fminf/fmaxf, which treat NaN differently;
// - the watertight sheared test (Woop, Benthin and Wald, JCGT 2013) with the f64 tie-break on
//   edges, as `geom::sheared_ray`;
// - the smallest (t, triangle index) wins, so the traversal order does not change a hit.

#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
#define CUDA_CALLABLE __host__ __device__ __forceinline__
#define KODAMA_DEVICE 1
typedef unsigned int u32;
typedef unsigned long long u64;
typedef unsigned char u8;
#define INF_F __int_as_float(0x7f800000)
#define NEG_INF_F __int_as_float(0xff800000)
#else
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#define CUDA_CALLABLE static inline
typedef uint32_t u32;
typedef uint64_t u64;
typedef uint8_t u8;
#define INF_F (__builtin_inff())
#define NEG_INF_F (-__builtin_inff())
#endif

// Children per node and triangles per leaf packet (`wide_bvh::WIDTH`, `tri_packet::LANES`).
#define WIDTH 8
#define LANES 4
// Traversal stack entries per thread; the host refuses a tree that needs more.
#define STACK_MAX 160

// `wide_bvh::Node` as `WideBvh::gpu_words` writes it: 256 bytes.
struct Node {
    float planes[6][WIDTH];
    u32 index[WIDTH];
    u8 count[WIDTH];
    u32 used;
    u32 pad[5];
};

// `tri_packet::TriPacket`: v[vertex][axis][lane], then the lanes' triangle indices.
struct TriPacket {
    float v[3][3][LANES];
    u32 prim[LANES];
};

struct Entry {
    u32 index;
    u32 count;
    float near_t;
};

// wide_bvh::PAD: 4 / 2^20, exact in f32, and 1 + PAD, exact too.
#define PAD 3.814697265625e-06f
#define ONE_PAD 1.000003814697265625f

CUDA_CALLABLE float min_sel(float a, float b) { return a < b ? a : b; }
CUDA_CALLABLE float max_sel(float a, float b) { return a > b ? a : b; }

CUDA_CALLABLE float abs_f(float x) {
#ifdef KODAMA_DEVICE
    return fabsf(x);
#else
    return std::fabs(x);
#endif
}

CUDA_CALLABLE float copysign_f(float m, float s) {
#ifdef KODAMA_DEVICE
    return copysignf(m, s);
#else
    return std::copysign(m, s);
#endif
}

CUDA_CALLABLE float padded(float t) { return t + abs_f(t) * PAD; }

// `sheared_ray::ShearedRay`.
struct Sheared {
    float o[3];
    int k[3];
    float s[3];
    float tmin;
};

CUDA_CALLABLE Sheared sheared_new(const float o[3], const float d[3], float tmin) {
    Sheared r;
    float ax = abs_f(d[0]), ay = abs_f(d[1]), az = abs_f(d[2]);
    int kz;
    if (ax > ay) {
        kz = ax > az ? 0 : 2;
    } else {
        kz = ay > az ? 1 : 2;
    }
    int kx = (kz + 1) % 3, ky = (kz + 2) % 3;
    if (d[kz] < 0.0f) {
        int t = kx;
        kx = ky;
        ky = t;
    }
    for (int a = 0; a < 3; a++) r.o[a] = o[a];
    r.k[0] = kx;
    r.k[1] = ky;
    r.k[2] = kz;
    r.s[0] = d[kx] / d[kz];
    r.s[1] = d[ky] / d[kz];
    r.s[2] = 1.0f / d[kz];
    r.tmin = tmin;
    return r;
}

CUDA_CALLABLE float edge_f64(float p, float q, float r, float s) {
    double a = (double)p * (double)q;
    double b = (double)r * (double)s;
    return (float)(a - b);
}

// `ShearedRay::intersect` on lane `lane` of a packet (which `TriPacket::intersect` equals bit for
// bit, lane by lane): the distance, or infinity on a miss.
CUDA_CALLABLE float tri_intersect(const Sheared& r, const TriPacket& p, int lane, float tmax) {
    int kx = r.k[0], ky = r.k[1], kz = r.k[2];
    float sx = r.s[0], sy = r.s[1], sz = r.s[2];
    float a[3], b[3], c[3];
    for (int i = 0; i < 3; i++) {
        a[i] = p.v[0][i][lane] - r.o[i];
        b[i] = p.v[1][i][lane] - r.o[i];
        c[i] = p.v[2][i][lane] - r.o[i];
    }
    float ax = a[kx] - sx * a[kz], ay = a[ky] - sy * a[kz];
    float bx = b[kx] - sx * b[kz], by = b[ky] - sy * b[kz];
    float cx = c[kx] - sx * c[kz], cy = c[ky] - sy * c[kz];
    float u = cx * by - cy * bx;
    float v = ax * cy - ay * cx;
    float w = bx * ay - by * ax;
    if (u == 0.0f || v == 0.0f || w == 0.0f) {
        u = edge_f64(cx, by, cy, bx);
        v = edge_f64(ax, cy, ay, cx);
        w = edge_f64(bx, ay, by, ax);
    }
    if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return INF_F;
    float det = u + v + w;
    if (det == 0.0f) return INF_F;
    float t = (u * sz * a[kz] + v * sz * b[kz] + w * sz * c[kz]) / det;
    return (t > r.tmin && t < tmax) ? t : INF_F;
}

// `wide_bvh::Slabs`.
struct Slabs {
    float o[3];
    float inv[3];
    float inv_far[3];
    int near_row[3];
    int far_row[3];
};

CUDA_CALLABLE Slabs slabs_new(const float o[3], const float d[3]) {
    Slabs s;
    for (int a = 0; a < 3; a++) {
        float c = d[a];
        if (abs_f(c) < 1e-20f) c = copysign_f(1e-20f, c + 0.0f);
        float inv = 1.0f / c;
        bool positive = inv > 0.0f;
        s.o[a] = o[a];
        s.inv[a] = inv;
        s.inv_far[a] = inv * ONE_PAD;
        s.near_row[a] = positive ? a : 3 + a;
        s.far_row[a] = positive ? 3 + a : a;
    }
    return s;
}

// `wide_bvh::Scalar::boxes`: a bit per child entered within [tmin, far], and entry distances.
CUDA_CALLABLE u32 boxes(const Node& node, const Slabs& s, float tmin, float far_t,
                        float near_out[WIDTH]) {
    u32 mask = 0;
    for (int i = 0; i < WIDTH; i++) {
        float nx = (node.planes[s.near_row[0]][i] - s.o[0]) * s.inv[0];
        float fx = (node.planes[s.far_row[0]][i] - s.o[0]) * s.inv_far[0];
        float ny = (node.planes[s.near_row[1]][i] - s.o[1]) * s.inv[1];
        float fy = (node.planes[s.far_row[1]][i] - s.o[1]) * s.inv_far[1];
        float nz = (node.planes[s.near_row[2]][i] - s.o[2]) * s.inv[2];
        float fz = (node.planes[s.far_row[2]][i] - s.o[2]) * s.inv_far[2];
        float tn = max_sel(max_sel(nx, ny), max_sel(nz, tmin));
        float tf = min_sel(min_sel(fx, fy), min_sel(fz, far_t));
        near_out[i] = tn;
        if (tn <= tf) mask |= 1u << i;
    }
    return mask;
}

CUDA_CALLABLE int ctz(u32 x) {
#ifdef KODAMA_DEVICE
    return __ffs(x) - 1;
#else
    return __builtin_ctz(x);
#endif
}

// The traversal of `closest_hit` and `any_hit`: with `any`, the first triangle met in
// (tmin, tmax) ends it (no (t, triangle) is then given).
CUDA_CALLABLE bool traverse(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                            const float o_in[3], const float d_in[3], float tmin, float tmax,
                            bool any, float* t_out, u32* prim_out) {
    if (n_nodes == 0) return false;
    float o[3], d[3];
    for (int a = 0; a < 3; a++) {
        o[a] = o_in[a];
        d[a] = d_in[a] + 0.0f;
    }
    Sheared ray = sheared_new(o, d, tmin);
    Slabs slabs = slabs_new(o, d);
    float best_t = tmax;
    u32 best_p = 0xffffffffu;
    Entry stack[STACK_MAX];
    int top = 0;
    Entry cur;
    cur.index = 0;
    cur.count = 0;
    cur.near_t = tmin;
    float limit = padded(best_t);
    for (;;) {
        if (cur.near_t <= limit) {
            if (cur.count != 0) {
                for (u32 k = 0; k < cur.count; k++) {
                    const TriPacket& p = packets[cur.index + k];
                    for (int lane = 0; lane < LANES; lane++) {
                        float t = tri_intersect(ray, p, lane, tmax);
                        u32 q = p.prim[lane];
                        if (t < tmax && t <= best_t && (t < best_t || q < best_p)) {
                            if (any) return true;
                            best_t = t;
                            best_p = q;
                        }
                    }
                }
                limit = padded(best_t);
            } else {
                const Node& node = nodes[cur.index];
                float near_t[WIDTH];
                u32 mask = boxes(node, slabs, tmin, limit, near_t);
                if (mask != 0) {
                    // Nearest child next, the others on the stack farthest first (the CPU's
                    // order, though any order gives the same hit).
                    Entry order[WIDTH];
                    int n = 0;
                    while (mask != 0) {
                        int i = ctz(mask);
                        mask &= mask - 1;
                        Entry e;
                        e.index = node.index[i];
                        e.count = node.count[i];
                        e.near_t = near_t[i];
                        int j = n;
                        while (j > 0 && order[j - 1].near_t < e.near_t) {
                            order[j] = order[j - 1];
                            j--;
                        }
                        order[j] = e;
                        n++;
                    }
                    for (int j = 0; j < n - 1; j++) stack[top++] = order[j];
                    cur = order[n - 1];
                    continue;
                }
            }
        }
        if (top == 0) break;
        cur = stack[--top];
    }
    if (best_p == 0xffffffffu) return false;
    *t_out = best_t;
    *prim_out = best_p;
    return true;
}

// `SceneRays::cast_index`: the closest (t, triangle) of `o + t d`, t in (tmin, tmax); returns
// false on a miss. `d` need not be canonical: -0.0 is made +0.0 first, as the CPU does.
CUDA_CALLABLE bool closest_hit(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                               const float o[3], const float d[3], float tmin, float tmax,
                               float* t_out, u32* prim_out) {
    return traverse(nodes, n_nodes, packets, o, d, tmin, tmax, false, t_out, prim_out);
}

// `SceneRays::occluded`: whether any triangle meets `o + t d` for t in (tmin, tmax). The same
// triangles as `closest_hit` tests, so the same answer as asking it for a hit, sooner.
CUDA_CALLABLE bool any_hit(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                           const float o[3], const float d[3], float tmin, float tmax) {
    float t;
    u32 p;
    return traverse(nodes, n_nodes, packets, o, d, tmin, tmax, true, &t, &p);
}

// One cast per ray; `rays` holds 8 floats a ray (origin, direction, tmin, tmax). A miss writes
// infinity and 0xffffffff.
CUDA_CALLABLE void cast_one(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                            const float* rays, u64 i, float* t_out, u32* prim_out) {
    const float* r = rays + 8 * i;
    float t;
    u32 p;
    if (closest_hit(nodes, n_nodes, packets, r, r + 3, r[6], r[7], &t, &p)) {
        t_out[i] = t;
        prim_out[i] = p;
    } else {
        t_out[i] = INF_F;
        prim_out[i] = 0xffffffffu;
    }
}


// One any-hit query per ray (8 floats a ray, as `cast_one`'s): 1 when something lies between.
CUDA_CALLABLE void occluded_one(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                                const float* rays, u64 i, u8* out) {
    const float* r = rays + 8 * i;
    out[i] = any_hit(nodes, n_nodes, packets, r, r + 3, r[6], r[7]) ? 1 : 0;
}

// ---------------------------------------------------------------------------------------------
// The radio map (`rf::radiomap::radio_map`, `Shooter::segment`): Sionna RT's shoot-and-bounce
// estimator, one thread per launched ray. The field is a complex 3-vector in f64 (`rf::field`),
// reflection and transmission use the ITU-R P.2040 slab coefficients (`rf::em::slab`) from a
// table over √cos θ, the event (specular or through) is drawn from the same hash as the CPU's,
// and every crossing of the plane adds |E|² Ω / (|cos θ| A_cell) to its cell. Sums are exact
// fixed-point integers (value · 2^FIX_SHIFT in 128 bits, two u64 words with carry), so the map
// is the same bits whatever order the threads add in.

#define FIX_SHIFT 100
#define EPS_M 1e-3

// The scalars of a map, as f64 (`MapConsts` in backend.rs writes them in this order).
enum {
    C_TX = 0,        // 3
    C_OMEGA = 3,
    C_X0 = 4,
    C_Y0 = 5,
    C_CELL = 6,
    C_Z = 7,
    C_S2 = 8,
    C_NRAYS = 9,
    C_DEPTH = 10,
    C_LOS = 11,
    C_REFLECT = 12,
    C_TRANSMIT = 13,
    C_WIDTH = 14,
    C_HEIGHT = 15,
    C_TABLE = 16,
    C_DIFFUSE = 17,
    C_SCAT = 18,
    C_FOL_AT_TX = 19,  // canopies the transmitter stands in (`FoliageDepth::at`)
    C_FOL_DB_M = 20,   // foliage loss, dB/m
    C_FOL_MAX = 21,    // P.833's saturation A_m, dB; 0 for the linear law
    C_FOL_MAT = 22,    // foliage's material index
    C_WAVELENGTH = 23, // metres
    C_WEDGE_LEN = 24,  // the lit wedges' total length, metres (diffraction only)
    C_WEDGES = 25,     // how many lit wedges
    C_ANT_PATTERN = 26, // the transmit antenna (`Antenna`): 0 isotropic, 1 dipole, 2 TR 38.901
    C_ANT_POL = 27,     // 0 V, 1 H
    C_ANT_ROT = 28,     // sin, cos of (bearing - 90°), then of the tilt (`Antenna::frame`)
    C_SCAT_ALPHA = 32,  // the diffuse lobe: -1 Lambertian, else the directive α_R
    C_COUNT = 33
};

struct Cx {
    double re, im;
};

CUDA_CALLABLE Cx cx(double re, double im) {
    Cx c;
    c.re = re;
    c.im = im;
    return c;
}
CUDA_CALLABLE Cx cadd(Cx a, Cx b) { return cx(a.re + b.re, a.im + b.im); }
CUDA_CALLABLE Cx csub(Cx a, Cx b) { return cx(a.re - b.re, a.im - b.im); }
CUDA_CALLABLE Cx cmul(Cx a, Cx b) { return cx(a.re * b.re - a.im * b.im, a.re * b.im + a.im * b.re); }
CUDA_CALLABLE Cx cscale(Cx a, double f) { return cx(a.re * f, a.im * f); }
CUDA_CALLABLE double cnorm2(Cx a) { return a.re * a.re + a.im * a.im; }

struct V3 {
    double x, y, z;
};
CUDA_CALLABLE V3 v3(double x, double y, double z) {
    V3 v;
    v.x = x;
    v.y = y;
    v.z = z;
    return v;
}
CUDA_CALLABLE V3 vadd(V3 a, V3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
CUDA_CALLABLE V3 vsub(V3 a, V3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
CUDA_CALLABLE V3 vmul(V3 a, double f) { return v3(a.x * f, a.y * f, a.z * f); }
CUDA_CALLABLE double vdot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
CUDA_CALLABLE V3 vcross(V3 a, V3 b) {
    return v3(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y);
}
CUDA_CALLABLE double dsqrt(double x) {
#ifdef KODAMA_DEVICE
    return sqrt(x);
#else
    return std::sqrt(x);
#endif
}
CUDA_CALLABLE V3 vnormalize(V3 a) { return vmul(a, 1.0 / dsqrt(vdot(a, a))); }
// glam's `any_orthonormal_vector` (Frisvad's, as revised by Duff et al. 2017).
CUDA_CALLABLE V3 any_orthonormal(V3 v) {
    double sign = v.z >= 0.0 ? 1.0 : -1.0;
    double a = -1.0 / (sign + v.z);
    double b = v.x * v.y * a;
    return v3(b, sign + v.y * v.y * a, -v.y);
}

struct Field {
    Cx c[3];
};

CUDA_CALLABLE double field_norm2(const Field& e) {
    return cnorm2(e.c[0]) + cnorm2(e.c[1]) + cnorm2(e.c[2]);
}
CUDA_CALLABLE Cx field_dot(const Field& e, V3 v) {
    return cadd(cadd(cscale(e.c[0], v.x), cscale(e.c[1], v.y)), cscale(e.c[2], v.z));
}
CUDA_CALLABLE Field combine(Cx a, V3 u, Cx b, V3 v) {
    Field f;
    f.c[0] = cadd(cscale(a, u.x), cscale(b, v.x));
    f.c[1] = cadd(cscale(a, u.y), cscale(b, v.y));
    f.c[2] = cadd(cscale(a, u.z), cscale(b, v.z));
    return f;
}
// `field::basis`: (⊥, ∥) of the plane of incidence of k on a surface of normal n.
CUDA_CALLABLE void basis(V3 k, V3 n, V3* perp, V3* par) {
    V3 c = vcross(k, n);
    *perp = vdot(c, c) > 1e-20 ? vnormalize(c) : any_orthonormal(k);
    *par = vcross(*perp, k);
}

// `rng::mix` (SplitMix64's finaliser) and `rng::unit`.
CUDA_CALLABLE u64 mix64(u64 z) {
    z = z + 0x9E3779B97F4A7C15ull;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}
CUDA_CALLABLE double unit01(u64 h) { return (double)(h >> 11) / 9007199254740992.0; }

CUDA_CALLABLE void sincos_d(double x, double* s, double* c) {
#ifdef KODAMA_DEVICE
    sincos(x, s, c);
#else
    *s = std::sin(x);
    *c = std::cos(x);
#endif
}

// libm on either compiler: CUDA's device functions, or the host's std:: ones.
#ifdef KODAMA_DEVICE
#define LIBM(f) f
#else
#define LIBM(f) std::f
#endif
CUDA_CALLABLE double cos_d(double x) { return LIBM(cos)(x); }
CUDA_CALLABLE double acos_d(double x) { return LIBM(acos)(x); }
CUDA_CALLABLE double asin_d(double x) { return LIBM(asin)(x); }
CUDA_CALLABLE double atan2_d(double y, double x) { return LIBM(atan2)(y, x); }
CUDA_CALLABLE double tan_d(double x) { return LIBM(tan)(x); }

CUDA_CALLABLE double abs_d(double x) { return x < 0.0 ? -x : x; }
CUDA_CALLABLE double min_d(double a, double b) { return a < b ? a : b; }

// The i-th of n points of the Fibonacci lattice (`fibonacci::fibonacci_sphere`, Sionna's).
CUDA_CALLABLE V3 lattice(u32 n, u32 i) {
    const double golden = 1.6180339887498949;
    double q = (double)i / golden;
    double x = q - (double)(u64)q;
    double y = n > 1 ? (double)i / (double)(n - 1) : 0.5;
    double phi = 2.0 * 3.141592653589793 * x;
    double z = 1.0 - 2.0 * y;
    double r2 = 1.0 - z * z;
    double r = dsqrt(r2 > 0.0 ? r2 : 0.0);
    double s, c;
    sincos_d(phi, &s, &c);
    return v3(r * c, r * s, z);
}

// Adds `v` (≥ 0) to cell `cell` of `acc` (two u64 words a cell, low first) as a fixed-point
// integer: integer sums do not depend on their order.
CUDA_CALLABLE void accumulate(u64* acc, u32 cell, double v) {
    const double two64 = 18446744073709551616.0;
    double x = v * 1267650600228229401496703205376.0;  // 2^FIX_SHIFT
    if (!(x > 0.0)) return;
    if (x >= two64 * two64) x = two64 * two64 * 0.9999999999999999;
    u64 hi = (u64)(x / two64);
    u64 lo = (u64)(x - (double)hi * two64);
    u64* w = acc + 2 * (u64)cell;
#ifdef KODAMA_DEVICE
    u64 old = atomicAdd((unsigned long long*)w, (unsigned long long)lo);
    u64 carry = old + lo < old ? 1 : 0;
    if (hi + carry != 0) atomicAdd((unsigned long long*)(w + 1), (unsigned long long)(hi + carry));
#else
    u64 old = w[0];
    w[0] = old + lo;
    w[1] += hi + (old + lo < old ? 1 : 0);
#endif
}

// Slab coefficients of material m at incidence cosine cos_t (either sign): the table holds, per
// material, `len` samples evenly spaced in √cos θ, each (R_TE, R_TM, T_TE, T_TM) as 8 f64.
CUDA_CALLABLE void slab_get(const double* slabs, u32 len, u32 m, double cos_t, Cx out[4]) {
    double c = cos_t < 0.0 ? -cos_t : cos_t;
    if (c > 1.0) c = 1.0;
    double x = dsqrt(c) * (double)(len - 1);
    u32 i = (u32)x;
    if (i > len - 2) i = len - 2;
    double f = x - (double)i;
    const double* a = slabs + ((u64)m * len + i) * 8;
    const double* b = a + 8;
    for (int k = 0; k < 4; k++) {
        Cx ca = cx(a[2 * k], a[2 * k + 1]);
        Cx cb = cx(b[2 * k], b[2 * k + 1]);
        out[k] = cadd(ca, cscale(csub(cb, ca), f));
    }
}

// `antenna::spherical_basis`: (θ̂, φ̂) of the unit direction k.
CUDA_CALLABLE void spherical_basis(V3 k, V3* th, V3* ph) {
    double rho = dsqrt(k.x * k.x + k.y * k.y);
    if (rho < 1e-12) {
        *ph = v3(0.0, 1.0, 0.0);
        *th = v3(1.0 * k.z, -0.0 * k.z, 0.0);
        return;
    }
    double cp = k.x / rho, sp = k.y / rho;
    *th = v3(k.z * cp, k.z * sp, -rho);
    *ph = v3(-sp, cp, 0.0);
}

// f64::signum: ±1 by the sign bit, so -0.0 gives -1.
CUDA_CALLABLE double signum_d(double x) {
#ifdef KODAMA_DEVICE
    return copysign(1.0, x);
#else
    return std::copysign(1.0, x);
#endif
}

// `radiomap::hemisphere`: a direction round the unit normal n, uniform in solid angle, from two
// uniforms (glam's `any_orthonormal_pair` for the tangents).
CUDA_CALLABLE V3 hemisphere(V3 n, double u1, double u2) {
    double z = u1;
    double r2 = 1.0 - z * z;
    double r = dsqrt(r2 > 0.0 ? r2 : 0.0);
    double phi = 2.0 * 3.141592653589793 * u2;
    double sign = signum_d(n.z);
    double a_ = -1.0 / (sign + n.z);
    double b_ = n.x * n.y * a_;
    V3 a = v3(1.0 + sign * n.x * n.x * a_, sign * b_, -sign * n.x);
    V3 b = v3(b_, sign + n.y * n.y * a_, -n.y);
    double s, c;
#ifdef KODAMA_DEVICE
    s = sin(phi);
    c = cos(phi);
#else
    s = std::sin(phi);
    c = std::cos(phi);
#endif
    return vnormalize(vadd(vadd(vmul(a, r * c), vmul(b, r * s)), vmul(n, z)));
}

CUDA_CALLABLE double pow10_d(double x) {
#ifdef KODAMA_DEVICE
    return pow(10.0, x);
#else
    return std::pow(10.0, x);
#endif
}

// `FoliageLoss::loss_db`: linear in the metres inside canopies, or P.833's saturating law.
CUDA_CALLABLE double foliage_loss_db(const double* k, double len) {
    double linear = k[C_FOL_DB_M] * len;
    double m = k[C_FOL_MAX];
    if (m == 0.0) return linear;
#ifdef KODAMA_DEVICE
    return m * -expm1(-linear / m);
#else
    return m * -std::expm1(-linear / m);
#endif
}

// `FoliageLoss::step_amplitude`: the field's factor over `len` more metres inside canopies after
// `before` metres (P.833 saturates on the whole path's metres).
CUDA_CALLABLE double foliage_step(const double* k, double before, double len) {
    if (k[C_FOL_MAX] == 0.0) return pow10_d(-k[C_FOL_DB_M] * len / 20.0);
    double added = foliage_loss_db(k, before + len) - foliage_loss_db(k, before);
    return pow10_d(-added / 20.0);
}

// `scattering::binomial`: n choose k, as the CPU's running product.
CUDA_CALLABLE double binomial_d(u32 n, u32 k) {
    double acc = 1.0;
    for (u32 i = 0; i < k; i++) acc = acc * (double)(n - i) / (double)(i + 1);
    return acc;
}

// x to a non-negative integer power, by repeated squaring (`f64::powi`).
CUDA_CALLABLE double powi_d(double x, u32 n) {
    double r = 1.0;
    while (n > 0) {
        if (n & 1u) r *= x;
        x *= x;
        n >>= 1;
    }
    return r;
}

// `scattering::directive_norm`: ∫ ((1 + cos ψ) / 2)^α dΩ over the hemisphere, at incidence θ_i.
CUDA_CALLABLE double directive_norm(u32 alpha, double theta_i) {
    double sn, c;
    sincos_d(theta_i, &sn, &c);
    double s2 = sn * sn;
    double sum = 0.0;
    for (u32 k = 0; k <= alpha; k++) {
        double i_k = 2.0 * 3.141592653589793 / (double)(k + 1);
        if (k % 2 == 1) {
            double inner = 0.0;
            for (u32 w = 0; w <= (k - 1) / 2; w++)
                inner += binomial_d(2 * w, w) * powi_d(s2, w) / powi_d(4.0, w);
            i_k = i_k * c * inner;
        }
        sum += binomial_d(alpha, k) * i_k;
    }
    return sum / powi_d(2.0, alpha);
}

// `scattering::pattern`: the diffuse lobe's density toward ks of a wave along ki off a surface
// of normal n (facing the wave): Lambertian (alpha < 0) or directive with α_R = alpha.
CUDA_CALLABLE double scattering_pattern(double alpha, V3 ki, V3 ks, V3 n) {
    double cos_s = vdot(ks, n);
    if (cos_s <= 0.0) return 0.0;
    if (alpha < 0.0) return cos_s / 3.141592653589793;
    V3 kr = vsub(ki, vmul(n, 2.0 * vdot(ki, n)));
    double ct = -vdot(ki, n);
    ct = ct < -1.0 ? -1.0 : (ct > 1.0 ? 1.0 : ct);
    u32 a = (u32)alpha;
    return powi_d((1.0 + vdot(kr, ks)) / 2.0, a) / directive_norm(a, acos_d(ct));
}

// A map surface following the terrain (`MapPlane::lifted`): its own tree, and per triangle the
// f32 unit normal `SceneRays::cast` gives (3 f32). n_nodes 0: the flat plane at C_Z.
struct Surface {
    const Node* nodes;
    u32 n_nodes;
    const TriPacket* packets;
    const float* normals;
};

// `cell_of`: the cell (row-major index) under (x, y), false outside the grid.
CUDA_CALLABLE bool cell_index(const double* k, double x, double y, u32* index) {
    double cell = k[C_CELL];
    double c = (x - k[C_X0]) / cell;
    double r = (k[C_Y0] - y) / cell;
    u32 width = (u32)k[C_WIDTH], height = (u32)k[C_HEIGHT];
    if (!(c >= 0.0 && r >= 0.0 && c < (double)width && r < (double)height)) return false;
    *index = (u32)r * width + (u32)c;
    return true;
}

// `RfScene::cast(o, d, tmin, tmax)`: the closest hit in f32 (tmax at most f32::MAX), its
// distance then refined in f64 against the triangle's plane (`RfScene::refine`); `tri` holds
// per triangle its unit normal and first vertex (6 f64). False on a miss, leaving the outputs
// as they were.
CUDA_CALLABLE bool cast_between(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                                const double* tri, V3 o, V3 d, double tmin, double tmax,
                                double* t_out, u32* tri_out) {
    float of[3] = {(float)o.x, (float)o.y, (float)o.z};
    float df[3] = {(float)d.x, (float)d.y, (float)d.z};
    float t32;
    u32 hit_tri;
    float tmax32 = tmax < 3.4028234663852886e38 ? (float)tmax : 3.40282347e38f;
    if (!closest_hit(nodes, n_nodes, packets, of, df, (float)tmin, tmax32, &t32, &hit_tri))
        return false;
    const double* tr = tri + 6 * (u64)hit_tri;
    V3 nn = v3(tr[0], tr[1], tr[2]);
    double denom = vdot(nn, d);
    double t64 = vdot(nn, vsub(v3(tr[3], tr[4], tr[5]), o)) / denom;
    double dt = t64 - (double)t32;
    if (dt < 0.0) dt = -dt;
    double ad = denom < 0.0 ? -denom : denom;
    if (ad > 1e-12 && dt <= 1e-3 * (1.0 + (double)t32)) {
        *t_out = t64 > tmin ? t64 : tmin;
    } else {
        *t_out = (double)t32;
    }
    *tri_out = hit_tri;
    return true;
}

// `RfScene::cast(o, d, EPS, ∞)`.
CUDA_CALLABLE bool cast_refined(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                                const double* tri, V3 o, V3 d, double* t_out, u32* tri_out) {
    return cast_between(nodes, n_nodes, packets, tri, o, d, EPS_M, 1.0 / 0.0, t_out, tri_out);
}

// `antenna::gain`: the pattern's power gain at (θ, φ) of the antenna's frame.
CUDA_CALLABLE double pattern_gain(u32 pattern, double theta, double phi) {
    if (pattern == 1) {
        double s = LIBM(sin)(theta);
        return 1.5 * (s * s);
    }
    // TR 38.901's element: 65° beamwidths, 30 dB floor, 8 dBi (degrees as `f64::to_degrees`).
    double th = theta * 57.29577951308232, ph = phi * 57.29577951308232;
    double v = (th - 90.0) / 65.0, h = ph / 65.0;
    double a_v = -min_d(12.0 * (v * v), 30.0);
    double a_h = -min_d(12.0 * (h * h), 30.0);
    double a = -min_d(-(a_v + a_h), 30.0);
    return pow10_d((a + 8.0) / 10.0);
}

// `Antenna::field`: the field the map's transmit antenna sends along the unit direction d (site
// frame): √G times θ̂ or φ̂ of the site frame, G evaluated in the antenna's rotated frame.
CUDA_CALLABLE Field antenna_field(const double* k, V3 d) {
    u32 pattern = (u32)k[C_ANT_PATTERN];
    double g = 1.0;
    if (pattern != 0) {
        double sa = k[C_ANT_ROT], ca = k[C_ANT_ROT + 1], st = k[C_ANT_ROT + 2],
               ct = k[C_ANT_ROT + 3];
        double x1 = ca * d.x - sa * d.y;
        double y1 = sa * d.x + ca * d.y;
        double z1 = d.z;
        double x2 = ct * x1 - st * z1;
        double z2 = st * x1 + ct * z1;
        double zc = z2 < -1.0 ? -1.0 : (z2 > 1.0 ? 1.0 : z2);
        g = pattern_gain(pattern, acos_d(zc), atan2_d(y1, x2));
    }
    double amp = dsqrt(g);
    // `antenna::spherical_basis`: at the poles φ̂ is +y and θ̂ = φ̂ × k.
    double rho = dsqrt(d.x * d.x + d.y * d.y);
    V3 th, ph;
    if (rho < 1e-12) {
        ph = v3(0.0, 1.0, 0.0);
        th = v3(1.0 * d.z, -0.0 * d.z, 0.0);
    } else {
        double cp = d.x / rho, sp = d.y / rho;
        th = v3(d.z * cp, d.z * sp, -rho);
        ph = v3(-sp, cp, 0.0);
    }
    V3 e = (u32)k[C_ANT_POL] == 0 ? th : ph;
    Field f;
    f.c[0] = cx(e.x * amp, 0.0);
    f.c[1] = cx(e.y * amp, 0.0);
    f.c[2] = cx(e.z * amp, 0.0);
    return f;
}

// One launched ray, the `lattice_index`-th, from the transmitter to the end of its bounces.
// `tri` holds per triangle its unit normal and first vertex (6 f64). `seen`, when not null,
// gets a 1 for the triangle the ray first lands on (foliage aside): the faces whose edges can
// diffract.
CUDA_CALLABLE void shoot(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                         const double* tri, const u32* material, const double* slabs,
                         const Surface& surface, const double* k, u32 lattice_index, u64* acc,
                         u8* seen) {
    u32 n_rays = (u32)k[C_NRAYS];
    u32 max_depth = (u32)k[C_DEPTH];
    double cell = k[C_CELL];
    double s2 = k[C_S2];
    V3 d = lattice(n_rays, lattice_index);
    V3 o = v3(k[C_TX], k[C_TX + 1], k[C_TX + 2]);
    Field e = antenna_field(k, d);
    double omega = k[C_OMEGA];
    u32 depth = 0;
    // Canopies the ray is inside (`FoliageDepth`) and the metres it has run in them.
    u32 canopies = (u32)k[C_FOL_AT_TX];
    double in_foliage = 0.0;
    u32 foliage_mat = (u32)k[C_FOL_MAT];
    for (;;) {
        bool inside = canopies > 0;
        double before = in_foliage;
        float of[3] = {(float)o.x, (float)o.y, (float)o.z};
        float df[3] = {(float)d.x, (float)d.y, (float)d.z};
        double t_end = 1.0 / 0.0;
        u32 hit_tri;
        bool hit = cast_refined(nodes, n_nodes, packets, tri, o, d, &t_end, &hit_tri);
        if ((depth > 0 || k[C_LOS] != 0.0) && surface.n_nodes == 0) {
            if (d.z != 0.0) {
                double t = (k[C_Z] - o.z) / d.z;
                u32 at;
                if (t > EPS_M && t < t_end && cell_index(k, o.x + d.x * t, o.y + d.y * t, &at)) {
                    double cosv = d.z < 0.0 ? -d.z : d.z;
                    if (cosv < 1e-6) cosv = 1e-6;
                    double weight = 1.0 / (cosv * (cell * cell / 1.0));
                    double a = inside ? foliage_step(k, before, t) : 1.0;
                    double v = field_norm2(e) * a * a * omega * weight;
                    accumulate(acc, at, v);
                }
            }
        } else if (depth > 0 || k[C_LOS] != 0.0) {
            // Every crossing of the terrain-following surface up to the hit, in turn
            // (`MapPlane::crossings`).
            float tmax = t_end < 3.4028234663852886e38 ? (float)t_end : 3.40282347e38f;
            double tmin = EPS_M;
            for (;;) {
                float ts;
                u32 sp;
                if (!closest_hit(surface.nodes, surface.n_nodes, surface.packets, of, df,
                                 (float)tmin, tmax, &ts, &sp))
                    break;
                double t = (double)ts;
                const float* nf = surface.normals + 3 * (u64)sp;
                V3 nn = v3((double)nf[0], (double)nf[1], (double)nf[2]);
                u32 at;
                if (cell_index(k, o.x + d.x * t, o.y + d.y * t, &at)) {
                    double cosv = vdot(d, nn);
                    if (cosv < 0.0) cosv = -cosv;
                    if (cosv < 1e-6) cosv = 1e-6;
                    double nz = nn.z < 0.0 ? -nn.z : nn.z;
                    if (nz < 1e-6) nz = 1e-6;
                    double weight = 1.0 / (cosv * (cell * cell / nz));
                    double a = inside ? foliage_step(k, before, t) : 1.0;
                    double v = field_norm2(e) * a * a * omega * weight;
                    accumulate(acc, at, v);
                }
                tmin = t + EPS_M;
                // Past 2^14 m an f32 step of EPS_M can round back onto the same hit.
                if (!((float)tmin > ts)) break;
            }
        }
        if (!hit) return;
        if (inside) {
            double a = foliage_step(k, before, t_end);
            for (int q = 0; q < 3; q++) e.c[q] = cscale(e.c[q], a);
            in_foliage += t_end;
        }
        o = vadd(o, vmul(d, t_end));
        const double* tr = tri + 6 * (u64)hit_tri;
        V3 n = v3(tr[0], tr[1], tr[2]);
        if (material[hit_tri] == foliage_mat) {
            // A canopy's boundary: in or out, straight on (`FoliageDepth::cross`).
            if (vdot(d, n) < 0.0)
                canopies++;
            else if (canopies > 0)
                canopies--;
            continue;
        }
        if (depth == 0 && seen) seen[hit_tri] = 1;
        depth++;
        if (depth > max_depth) return;
        double dn = vdot(d, n);
        Cx co[4];
        slab_get(slabs, (u32)k[C_TABLE], material[hit_tri], dn, co);
        double pr = cnorm2(co[0]) + cnorm2(co[1]);
        double pt = cnorm2(co[2]) + cnorm2(co[3]);
        double p_spec = k[C_REFLECT] != 0.0 ? pr * (1.0 - s2) : 0.0;
        double p_diff = k[C_DIFFUSE] != 0.0 ? pr * s2 : 0.0;
        double p_tran = k[C_TRANSMIT] != 0.0 ? pt : 0.0;
        double total = p_spec + p_diff + p_tran;
        if (total <= 0.0) return;
        u64 seed = mix64(((u64)lattice_index * 0x9E3779B97F4A7C15ull) ^ (u64)depth);
        double u = unit01(seed) * total;
        V3 perp, par;
        basis(d, n, &perp, &par);
        if (u < p_spec) {
            V3 kr = vsub(d, vmul(n, 2.0 * vdot(d, n)));
            V3 par_r = vcross(perp, kr);
            Field e2 = combine(cmul(co[0], field_dot(e, perp)), perp, cmul(co[1], field_dot(e, par)),
                               par_r);
            double w = dsqrt((1.0 - s2) * total / p_spec);
            for (int q = 0; q < 3; q++) e.c[q] = cscale(e2.c[q], w);
            d = kr;
        } else if (u < p_spec + p_diff) {
            // Diffuse (Lambertian): uniform on the hemisphere the wave came from, weighted by the
            // pattern and the specular field's share; the new tube spans 2π.
            V3 side = dn < 0.0 ? n : vmul(n, -1.0);
            V3 ko = hemisphere(side, unit01(mix64(seed ^ 1ull)), unit01(mix64(seed ^ 2ull)));
            V3 kr = vsub(d, vmul(n, 2.0 * vdot(d, n)));
            V3 par_r = vcross(perp, kr);
            Field e_spec = combine(cmul(co[0], field_dot(e, perp)), perp,
                                   cmul(co[1], field_dot(e, par)), par_r);
            double before = field_norm2(e);
            double gamma = dsqrt(field_norm2(e_spec) / (before > 1e-300 ? before : 1e-300));
            double fp = scattering_pattern(k[C_SCAT_ALPHA], d, ko, side);
            V3 th_i, ph_i, th_o, ph_o;
            spherical_basis(d, &th_i, &ph_i);
            spherical_basis(ko, &th_o, &ph_o);
            Cx e_th = field_dot(e, th_i), e_ph = field_dot(e, ph_i);
            double w = k[C_SCAT] * gamma * dsqrt(fp * omega * total / p_diff);
            Field e2 = combine(e_th, th_o, e_ph, ph_o);
            for (int q = 0; q < 3; q++) e.c[q] = cscale(e2.c[q], w);
            d = ko;
            omega = 2.0 * 3.141592653589793;
        } else {
            Field e2 = combine(cmul(co[2], field_dot(e, perp)), perp, cmul(co[3], field_dot(e, par)),
                               par);
            double w = dsqrt(total / p_tran);
            for (int q = 0; q < 3; q++) e.c[q] = cscale(e2.c[q], w);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The link search's sequence search (`rf::sequences::reflection_sequences`): each launched ray
// walks its tree of branches depth first, reflecting off every surface it meets and, with
// transmission, also going through it, and every sequence of surfaces it reflects off goes into
// one hash set shared by all threads. The set is the CPU's exactly (the same casts, to the bit,
// in f64 between them), whatever order the threads insert in: the host sorts it.

// Most interactions a path may have (`path::MAX_DEPTH`).
#define SEQ_DEPTH_MAX 32
#define SEQ_NONE 0xffffffffu

// The scalars of a sequence search, as f64 (`SearchParams` in link_search.rs writes them).
enum {
    S_TX = 0,  // 3
    S_NRAYS = 3,
    S_DEPTH = 4,
    S_TRANSMIT = 5,
    S_FOL_MAT = 6,
    S_COUNT = 7
};

// The set: open addressing over `slots` (a power of two; 0 empty, else 1 + the sequence's
// index), the sequences themselves in `seqs`, `stride` words each (its length, then its
// triangles). A thread writes its sequence before it claims a slot with one compare-and-swap, so
// a slot seen taken already holds what it names: no locks, no waiting. Two threads racing for a
// slot with the same sequence leave the loser's copy unnamed, which the host never reads.
// counters[0] counts the sequences written, counters[1] becomes 1 when `seqs` ran out (the host
// grows the set and searches again).
struct SeqSet {
    u32* slots;
    u32 slot_mask;
    u32* seqs;
    u32 stride;
    u32 seq_cap;
    u32* counters;
};

// Adds 1 to *p, returning what it was: atomically on the device.
CUDA_CALLABLE u32 bump(u32* p) {
#ifdef KODAMA_DEVICE
    return atomicAdd(p, 1u);
#else
    return (*p)++;
#endif
}

CUDA_CALLABLE u32 load_word(const u32* p) {
#ifdef KODAMA_DEVICE
    return *(const volatile u32*)p;
#else
    return *p;
#endif
}

CUDA_CALLABLE u32 claim(u32* p, u32 expected, u32 value) {
#ifdef KODAMA_DEVICE
    return atomicCAS(p, expected, value);
#else
    u32 old = *p;
    if (old == expected) *p = value;
    return old;
#endif
}

// What this thread wrote is seen by a thread that sees the slot naming it (and the reverse).
CUDA_CALLABLE void publish() {
#ifdef KODAMA_DEVICE
    __threadfence();
#endif
}

CUDA_CALLABLE u64 seq_hash(const u32* path, u32 len) {
    u64 h = mix64((u64)len);
    for (u32 i = 0; i < len; i++) h = mix64(h ^ (u64)path[i]);
    return h;
}

CUDA_CALLABLE bool seq_equal(const u32* stored, const u32* path, u32 len) {
    if (load_word(stored) != len) return false;
    for (u32 i = 0; i < len; i++)
        if (load_word(stored + 1 + i) != path[i]) return false;
    return true;
}

// Adds path[0..len) to the set unless it is there.
CUDA_CALLABLE void seq_insert(const SeqSet& set, const u32* path, u32 len) {
    u64 h = seq_hash(path, len);
    u32 mine = 0;
    for (u32 probe = 0; probe <= set.slot_mask; probe++) {
        u32* slot = set.slots + ((u32)(h + probe) & set.slot_mask);
        u32 v = load_word(slot);
        if (v == 0) {
            if (mine == 0) {
                u32 at = bump(&set.counters[0]);
                if (at >= set.seq_cap) {
                    set.counters[1] = 1;
                    return;
                }
                u32* out = set.seqs + (u64)at * set.stride;
                out[0] = len;
                for (u32 i = 0; i < len; i++) out[1 + i] = path[i];
                publish();
                mine = at + 1;
            }
            v = claim(slot, 0, mine);
            if (v == 0) return;
        }
        publish();
        if (seq_equal(set.seqs + (u64)(v - 1) * set.stride, path, len)) return;
    }
    set.counters[1] = 1;
}

// A branch of a ray's tree waiting its turn: where it starts, where it goes, its interactions so
// far, the length of its sequence and the surface that sequence ends on (SEQ_NONE when the
// branch went through or past a surface, its sequence its parent's).
struct Branch {
    V3 o, d;
    u32 depth, len, tri;
};

// The launched ray `lattice_index`: every branch of its tree, as `chunk_sequences` follows them.
// Depth first with the reflected branch pushed under the transmitted one, the stack holds at
// most one waiting branch per depth and the one on top; path[0..len) is a branch's sequence
// when it is popped, since only deeper branches wrote past it meanwhile.
CUDA_CALLABLE void search(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                          const double* tri, const u32* material, const double* k,
                          u32 lattice_index, const SeqSet& set) {
    u32 max_depth = (u32)k[S_DEPTH];
    bool transmit = k[S_TRANSMIT] != 0.0;
    u32 foliage_mat = (u32)k[S_FOL_MAT];
    Branch stack[SEQ_DEPTH_MAX + 2];
    u32 path[SEQ_DEPTH_MAX];
    u32 top = 0;
    Branch first = {v3(k[S_TX], k[S_TX + 1], k[S_TX + 2]), lattice((u32)k[S_NRAYS], lattice_index),
                    0, 0, SEQ_NONE};
    stack[top++] = first;
    while (top > 0) {
        Branch b = stack[--top];
        if (b.tri != SEQ_NONE) path[b.len - 1] = b.tri;
        double t;
        u32 h;
        if (!cast_refined(nodes, n_nodes, packets, tri, b.o, b.d, &t, &h)) continue;
        V3 p = vadd(b.o, vmul(b.d, t));
        if (material[h] == foliage_mat) {
            Branch on = {p, b.d, b.depth, b.len, SEQ_NONE};
            stack[top++] = on;
            continue;
        }
        if (b.depth + 1 > max_depth) continue;
        const double* tr = tri + 6 * (u64)h;
        V3 n = v3(tr[0], tr[1], tr[2]);
        path[b.len] = h;
        seq_insert(set, path, b.len + 1);
        // `field::mirror`: k − 2 (k · n) n.
        Branch reflected = {p, vsub(b.d, vmul(n, 2.0 * vdot(b.d, n))), b.depth + 1, b.len + 1, h};
        stack[top++] = reflected;
        if (transmit) {
            Branch through = {p, b.d, b.depth + 1, b.len, SEQ_NONE};
            stack[top++] = through;
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The lattice's patch order (`fibonacci::patch_order`) on the device: the rays of a chunk cut into
// rows of latitude, each row counting-sorted by azimuth bin. A row's bins follow the previous
// row's, so the chunk is one counting sort by (row's first bin + bin), stable in k: sorting each
// bin's few entries by k after an unordered scatter gives exactly the stable sort's order. The
// rows come from one thread (a handful of square roots a row); the rest is split over a block's
// threads in phases, which the host twin runs one after another (its scatter visits k out of
// order, so the bins' sort is exercised there too).

#define PATCH 64
// Rays a block orders, at most (backend.rs orders chunks of this size).
#define ORDER_CHUNK 65536
// Threads of a `kodama_order` block (`ORDER_THREADS` in backend.rs).
#define ORDER_THREADS 256
// Rows a chunk can have: every row but the last has at least PATCH rays.
#define ORDER_ROWS (ORDER_CHUNK / PATCH + 2)

CUDA_CALLABLE double round_d(double x) {
#ifdef KODAMA_DEVICE
    return round(x);
#else
    return std::round(x);
#endif
}

CUDA_CALLABLE double golden_ratio() { return (1.0 + dsqrt(5.0)) / 2.0; }

// `patch_order`'s `square_row`: rays in a row whose patches are square, k rays into the chunk.
CUDA_CALLABLE double square_row(u32 n, u32 start, double k) {
    double z = 1.0 - 2.0 * ((double)start + k) / (double)(n - 1);
    double r2 = 1.0 - z * z;
    return 8.0 * dsqrt(r2 > 0.0 ? r2 : 0.0) * dsqrt(3.141592653589793 * (double)n);
}

// The rows of rays `start..start + len` of an n-ray lattice (len already within n): row r holds
// rays row_start[r]..row_start[r + 1] (offsets from start) and bins bin_off[r]..bin_off[r + 1] of
// the chunk. Returns the row count. A chunk `patch_order` leaves in lattice order is one row of
// one bin (the bin's sort by k keeps it so).
CUDA_CALLABLE u32 patch_rows(u32 n, u32 start, u32 len, u32* row_start, u32* bin_off) {
    row_start[0] = 0;
    bin_off[0] = 0;
    if (n <= 1 || len <= PATCH) {
        row_start[1] = len;
        bin_off[1] = 1;
        return 1;
    }
    u32 rows = 0, row = 0;
    while (row < len) {
        double guess = square_row(n, start, (double)row);
        if (!(guess > (double)PATCH)) guess = (double)PATCH;
        double m = square_row(n, start, (double)row + guess / 2.0);
        u32 mm = (u32)round_d(m / (double)PATCH);
        if (mm < 1) mm = 1;
        mm *= PATCH;
        if (mm > len - row) mm = len - row;
        if (len - row - mm < mm / 2) mm = len - row;
        u32 bins = mm / 4 > 1 ? mm / 4 : 1;
        row_start[rows + 1] = row + mm;
        bin_off[rows + 1] = bin_off[rows] + bins;
        rows++;
        row += mm;
    }
    return rows;
}

// The chunk's bin of ray `start + k`: its row's first bin plus its azimuth's bin in the row.
CUDA_CALLABLE u32 patch_key(u32 start, u32 k, const u32* row_start, const u32* bin_off,
                            u32 rows) {
    u32 lo = 0, hi = rows;
    while (hi - lo > 1) {
        u32 mid = (lo + hi) / 2;
        if (row_start[mid] <= k)
            lo = mid;
        else
            hi = mid;
    }
    u32 bins = bin_off[lo + 1] - bin_off[lo];
    double q = (double)(start + k) / golden_ratio();
    double x = q - (double)(u64)q;
    u32 b = (u32)(x * (double)bins);
    if (b > bins - 1) b = bins - 1;
    return bin_off[lo] + b;
}

// The phases of one chunk's sort, thread `tid` of `threads`. `count` has a word per bin and one
// more (bin_off[rows] + 1), `partial` a word per thread.
struct OrderChunk {
    u32 n, start, len, rows, base;
    const u32* row_start;
    const u32* bin_off;
    u32* count;
    u32* partial;
    u32* out;
};

CUDA_CALLABLE void order_zero(const OrderChunk& c, u32 tid, u32 threads) {
    for (u32 i = tid; i <= c.bin_off[c.rows]; i += threads) c.count[i] = 0;
}
// count[b + 1] = rays in bin b.
CUDA_CALLABLE void order_histogram(const OrderChunk& c, u32 tid, u32 threads) {
    for (u32 k = tid; k < c.len; k += threads)
        bump(&c.count[patch_key(c.start, k, c.row_start, c.bin_off, c.rows) + 1]);
}
// The prefix sum of count, in three phases: each thread's segment, the segments' totals (one
// thread), the totals added back: count[b] = rays in bins before b.
CUDA_CALLABLE void order_segment(const OrderChunk& c, u32 tid, u32 threads, u32* lo, u32* hi) {
    u32 words = c.bin_off[c.rows] + 1;
    u32 seg = (words + threads - 1) / threads;
    *lo = tid * seg < words ? tid * seg : words;
    *hi = *lo + seg < words ? *lo + seg : words;
}
CUDA_CALLABLE void order_scan_segment(const OrderChunk& c, u32 tid, u32 threads) {
    u32 lo, hi, s = 0;
    order_segment(c, tid, threads, &lo, &hi);
    for (u32 i = lo; i < hi; i++) {
        s += c.count[i];
        c.count[i] = s;
    }
    c.partial[tid] = s;
}
CUDA_CALLABLE void order_scan_totals(const OrderChunk& c, u32 threads) {
    u32 s = 0;
    for (u32 t = 0; t < threads; t++) {
        u32 v = c.partial[t];
        c.partial[t] = s;
        s += v;
    }
}
CUDA_CALLABLE void order_scan_add(const OrderChunk& c, u32 tid, u32 threads) {
    u32 lo, hi;
    order_segment(c, tid, threads, &lo, &hi);
    for (u32 i = lo; i < hi; i++) c.count[i] += c.partial[tid];
}
// Every ray to a free place of its bin, in any order; count[b] ends as the end of bin b.
CUDA_CALLABLE void order_scatter(const OrderChunk& c, u32 tid, u32 threads) {
    for (u32 k = tid; k < c.len; k += threads) {
        u32 at = bump(&c.count[patch_key(c.start, k, c.row_start, c.bin_off, c.rows)]);
        c.out[at] = c.base + k;
    }
}
// Each bin's rays by k (a few a bin): the stable counting sort's order.
CUDA_CALLABLE void order_sort_bins(const OrderChunk& c, u32 tid, u32 threads) {
    for (u32 b = tid; b < c.bin_off[c.rows]; b += threads) {
        u32 lo = b == 0 ? 0 : c.count[b - 1], hi = c.count[b];
        for (u32 i = lo + 1; i < hi; i++) {
            u32 v = c.out[i], j = i;
            while (j > lo && c.out[j - 1] > v) {
                c.out[j] = c.out[j - 1];
                j--;
            }
            c.out[j] = v;
        }
    }
}

// ---------------------------------------------------------------------------------------------
// First-order edge diffraction in the map (`rf::radiomap_diffraction`, Sionna RT 2.2's
// estimator): a sample per launched ray picks a lit wedge in proportion to its length, a point
// q on it and an angle round it; the diffracted ray leaves q along the Keller cone and adds
// |E_d|² times the map area a unit of (edge length, cone angle) maps onto, over the samples its
// wedge drew, to each cell it crosses. The field over the edge is the UTD of `rf::utd` and
// `rf::diffraction` (Kouyoumjian-Pathak with Luebbers' face reflection factors, bounded by the
// wedge's size), the faces' coefficients from the slab table. Scenes with foliage are refused
// by the host.

#define PI_D 3.141592653589793
// Sionna's offset of the visibility point outside the corner, its shortest leg, the clearance
// of a leg's ends when looking for surfaces across it, metres (`radiomap_diffraction`).
#define OUTSIDE_CORNER_M 5e-2
#define MIN_LEG_M 1e-2
#define LEG_EPS_M 1e-2
// Salts the sample hashes apart from the shoot-and-bounce draws.
#define DIFF_SALT 0xD1FFAC7100000001ull


CUDA_CALLABLE double vlength(V3 a) { return dsqrt(vdot(a, a)); }
// glam's `normalize_or_zero`.
CUDA_CALLABLE V3 vnormalize_or_zero(V3 a) {
    double r = 1.0 / vlength(a);
    if (r > 0.0 && r < 1.0 / 0.0) return vmul(a, r);
    return v3(0.0, 0.0, 0.0);
}
CUDA_CALLABLE V3 vdiv(V3 a, double s) { return v3(a.x / s, a.y / s, a.z / s); }
CUDA_CALLABLE V3 vneg(V3 a) { return v3(-a.x, -a.y, -a.z); }

CUDA_CALLABLE Cx cdiv(Cx a, Cx b) {
    double n = b.re * b.re + b.im * b.im;
    return cx((a.re * b.re + a.im * b.im) / n, (a.im * b.re - a.re * b.im) / n);
}
CUDA_CALLABLE Cx cpolar(double r, double theta) {
    double sn, cs;
    sincos_d(theta, &sn, &cs);
    return cx(r * cs, r * sn);
}
CUDA_CALLABLE double cabs_d(Cx a) { return dsqrt(a.re * a.re + a.im * a.im); }

// A wedge as the host uploads it (`Wedge` in rf::diffraction), WEDGE_WORDS f64: a, e, length,
// n0, nn, n, tri0, trin, then its size (has_size, reach0, reachn, run).
#define WEDGE_WORDS 20
struct WedgeD {
    V3 a, e;
    double length;
    V3 n0, nn;
    double n;
    u32 tri0, trin;
    bool has_size;
    double reach0, reachn, run;
};

CUDA_CALLABLE WedgeD wedge_at(const double* w) {
    WedgeD x;
    x.a = v3(w[0], w[1], w[2]);
    x.e = v3(w[3], w[4], w[5]);
    x.length = w[6];
    x.n0 = v3(w[7], w[8], w[9]);
    x.nn = v3(w[10], w[11], w[12]);
    x.n = w[13];
    x.tri0 = (u32)w[14];
    x.trin = (u32)w[15];
    x.has_size = w[16] != 0.0;
    x.reach0 = w[17];
    x.reachn = w[18];
    x.run = w[19];
    return x;
}

// `Wedge::facing`: labelled so that its 0-face is one a wave along ki meets from outside.
CUDA_CALLABLE WedgeD wedge_facing(const WedgeD& w, V3 ki) {
    double c0 = vdot(ki, w.n0), cn = vdot(ki, w.nn);
    bool keep = (c0 <= 0.0 && cn <= 0.0) ? c0 <= cn : c0 <= 0.0;
    if (keep) return w;
    WedgeD f = w;
    f.a = vadd(w.a, vmul(w.e, w.length));
    f.e = vneg(w.e);
    f.n0 = w.nn;
    f.nn = w.n0;
    f.tri0 = w.trin;
    f.trin = w.tri0;
    f.reach0 = w.reachn;
    f.reachn = w.reach0;
    return f;
}

// `keller_cone`: the direction at cone angle phi from the 0-face on the cone of a wave along ki.
CUDA_CALLABLE V3 keller_cone(const WedgeD& w, V3 ki, double phi) {
    V3 t0 = vnormalize(vcross(w.n0, w.e));
    double along = vdot(ki, w.e);
    V3 e_fwd = along > 0.0 ? w.e : vneg(w.e);
    double cos_b = min_d(abs_d(along), 1.0);
    double sin_b = dsqrt(1.0 - cos_b * cos_b);
    double sp, cp;
    sincos_d(phi, &sp, &cp);
    return vnormalize(vadd(vadd(vmul(w.n0, sp * sin_b), vmul(t0, cp * sin_b)), vmul(e_fwd, cos_b)));
}

// `face_angle`: the angle of s (away from the edge) from the 0-face, in [0, 2π).
CUDA_CALLABLE double face_angle(const WedgeD& w, V3 s) {
    V3 t0 = vcross(w.n0, w.e);
    V3 st = vnormalize_or_zero(vsub(s, vmul(w.e, vdot(s, w.e))));
    double sgn = vdot(st, w.n0) >= 0.0 ? 1.0 : -1.0;
    double c = vdot(st, t0);
    c = c < -1.0 ? -1.0 : (c > 1.0 ? 1.0 : c);
    return PI_D - (PI_D - acos_d(c)) * sgn;
}

// `utd::fresnel_integrals` (Numerical Recipes' frenel): (S(x), C(x)).
CUDA_CALLABLE void fresnel_integrals(double x, double* s_out, double* c_out) {
    const double EPS = 1e-15, FPMIN = 1e-300;
    const int MAXIT = 200;
    double ax = abs_d(x);
    double s, c;
    if (ax < dsqrt(FPMIN)) {
        s = 0.0;
        c = ax;
    } else if (ax <= 1.5) {
        double fact = PI_D / 2.0 * ax * ax;
        double sum = 0.0, sums = 0.0, sumc = ax;
        double sign = 1.0, term = ax, n = 3.0;
        bool odd = true;
        for (int k = 1; k < MAXIT; k++) {
            term *= fact / (double)k;
            sum += sign * term / n;
            double test = abs_d(sum) * EPS;
            if (odd) {
                sign = -sign;
                sums = sum;
                sum = sumc;
            } else {
                sumc = sum;
                sum = sums;
            }
            if (term < test) break;
            odd = !odd;
            n += 2.0;
        }
        s = sums;
        c = sumc;
    } else {
        double pix2 = PI_D * ax * ax;
        Cx b = cx(1.0, -pix2);
        Cx cc = cx(1.0 / FPMIN, 0.0);
        Cx d = cdiv(cx(1.0, 0.0), b);
        Cx h = d;
        double n = -1.0;
        for (int k = 2; k < MAXIT; k++) {
            n += 2.0;
            double a = -n * (n + 1.0);
            b = cadd(b, cx(4.0, 0.0));
            d = cdiv(cx(1.0, 0.0), cadd(cscale(d, a), b));
            cc = cadd(b, cdiv(cx(a, 0.0), cc));
            Cx del = cmul(cc, d);
            h = cmul(h, del);
            if (abs_d(del.re - 1.0) + abs_d(del.im) < EPS) break;
        }
        h = cmul(h, cx(ax, -ax));
        Cx one_minus = csub(cx(1.0, 0.0), cmul(cpolar(1.0, 0.5 * pix2), h));
        Cx cs = cmul(cx(0.5, 0.5), one_minus);
        s = cs.im;
        c = cs.re;
    }
    if (x < 0.0) {
        s = -s;
        c = -c;
    }
    *s_out = s;
    *c_out = c;
}

// `utd::transition`: the UTD's transition function F(x).
CUDA_CALLABLE Cx transition_f(double x) {
    if (x <= 0.0) return cx(0.0, 0.0);
    double s, c;
    fresnel_integrals(dsqrt(2.0 * x / PI_D), &s, &c);
    Cx a = cscale(cpolar(1.0, x), dsqrt(PI_D * x / 2.0));
    return cmul(a, csub(cx(1.0, 1.0), cscale(cx(s, c), 2.0)));
}

CUDA_CALLABLE double utd_a(double n, double beta, bool plus) {
    double big_n = plus ? round_d((beta + PI_D) / (2.0 * n * PI_D))
                        : round_d((beta - PI_D) / (2.0 * n * PI_D));
    double cs = cos_d((2.0 * n * PI_D * big_n - beta) / 2.0);
    return 2.0 * (cs * cs);
}

CUDA_CALLABLE Cx utd_term(Cx factor, double n, double sign, double beta, bool plus, double kl) {
    if (abs_d(tan_d((PI_D + sign * beta) / (2.0 * n))) < 1e-9) beta = beta + 1e-7;
    double cot = 1.0 / tan_d((PI_D + sign * beta) / (2.0 * n));
    return cmul(cscale(factor, cot), transition_f(kl * utd_a(n, beta, plus)));
}

// `utd::wedge_coefficients`: D1..D4 of Kouyoumjian and Pathak.
CUDA_CALLABLE void wedge_coefficients(double n, double phi, double phi_i, double beta0, double k,
                                      double l, Cx d[4]) {
    double sb, cb;
    sincos_d(beta0, &sb, &cb);
    Cx minus = cscale(cpolar(1.0, -PI_D / 4.0), -1.0);
    double den = 2.0 * n * dsqrt(2.0 * PI_D * k) * sb;
    Cx factor = cx(minus.re / den, minus.im / den);
    double kl = k * l;
    d[0] = utd_term(factor, n, 1.0, phi - phi_i, true, kl);
    d[1] = utd_term(factor, n, -1.0, phi - phi_i, false, kl);
    d[2] = utd_term(factor, n, 1.0, phi + phi_i, true, kl);
    d[3] = utd_term(factor, n, -1.0, phi + phi_i, false, kl);
}

// `bounded_by_size`: no more than a wedge of its size can diffract.
CUDA_CALLABLE void bounded_by_size(Cx d[4], const WedgeD& w, double k, double sin_b, double si,
                                   double so) {
    double fresnel_zone = dsqrt(2.0 * PI_D / k / (sin_b * sin_b * (1.0 / si + 1.0 / so)));
    double along = min_d(w.run / fresnel_zone, 1.0);
    double reach[2] = {w.reachn, w.reach0};
    for (int j = 0; j < 2; j++) {
        double most = 0.5 * reach[j] * dsqrt(k / (2.0 * PI_D)) / sin_b;
        double norm = cabs_d(d[2 + j]);
        if (norm > most) d[2 + j] = cscale(d[2 + j], most / norm);
    }
    for (int j = 0; j < 4; j++) d[j] = cscale(d[j], along);
}

// `face_reflection`: a face's reflection of a wave along ki, as a matrix on edge-fixed
// components ((φ, β) in, (φ, β) of the reflected direction out).
CUDA_CALLABLE void face_reflection(const double* slabs, u32 table, u32 mat, V3 normal, V3 ki,
                                   V3 phi_in, V3 beta_in, V3 e, Cx r[2][2]) {
    double c = min_d(abs_d(vdot(ki, normal)), 1.0);
    Cx co[4];
    slab_get(slabs, table, mat, c, co);
    V3 kr = vsub(ki, vmul(normal, 2.0 * vdot(ki, normal)));
    V3 phi_out = vneg(vnormalize(vcross(kr, e)));
    V3 beta_out = vcross(phi_out, kr);
    V3 perp, par;
    basis(ki, normal, &perp, &par);
    V3 par_r = vcross(perp, kr);
    V3 ins[2] = {phi_in, beta_in};
    V3 outs[2] = {phi_out, beta_out};
    for (int col = 0; col < 2; col++) {
        // `field::reflect` of the real field ins[col].
        Cx a = cmul(co[0], cx(vdot(ins[col], perp), 0.0));
        Cx b = cmul(co[1], cx(vdot(ins[col], par), 0.0));
        Field f = combine(a, perp, b, par_r);
        for (int row = 0; row < 2; row++) r[row][col] = field_dot(f, outs[row]);
    }
}

// `diffracted_field`: the field at rx of a wave leaving tx with field e_tx (at unit distance),
// over wedge w at q (spreading included, propagation phase not); false when either end is
// inside the wedge.
CUDA_CALLABLE bool diffracted_field(const double* slabs, const u32* material, const double* k,
                                    const WedgeD& w0, V3 q, V3 tx, V3 rx, const Field& e_tx,
                                    Field* out) {
    V3 qi = vsub(q, tx), qo = vsub(rx, q);
    double si = vlength(qi), so = vlength(qo);
    V3 ki = vdiv(qi, si), ko = vdiv(qo, so);
    WedgeD w = wedge_facing(w0, ki);
    double phi_i = face_angle(w, vneg(ki));
    double phi = face_angle(w, ko);
    double limit = w.n * PI_D;
    if (!(phi_i > 0.0 && phi_i < limit && phi > 0.0 && phi < limit)) return false;
    double sin_b = vlength(vcross(ki, w.e));
    if (sin_b < 1e-6) return false;
    double beta0 = asin_d(min_d(sin_b, 1.0));
    double kw = 2.0 * PI_D / k[C_WAVELENGTH];
    double l = si * so * sin_b * sin_b / (si + so);
    Cx d[4];
    wedge_coefficients(w.n, phi, phi_i, beta0, kw, l, d);
    if (w.has_size) bounded_by_size(d, w, kw, sin_b, si, so);
    V3 phi_hat_i = vnormalize(vcross(ki, w.e));
    V3 beta_hat_i = vcross(phi_hat_i, ki);
    V3 phi_hat_o = vneg(vnormalize(vcross(ko, w.e)));
    V3 beta_hat_o = vcross(phi_hat_o, ko);
    u32 table = (u32)k[C_TABLE];
    Cx r0[2][2], rn[2][2];
    face_reflection(slabs, table, material[w.tri0], w.n0, ki, phi_hat_i, beta_hat_i, w.e, r0);
    face_reflection(slabs, table, material[w.trin], w.nn, ki, phi_hat_i, beta_hat_i, w.e, rn);
    Cx e_in[2] = {field_dot(e_tx, phi_hat_i), field_dot(e_tx, beta_hat_i)};
    double spread = dsqrt(1.0 / (si * so * (si + so)));
    Cx comp[2];
    for (int i = 0; i < 2; i++) {
        Cx apply_n = cadd(cmul(rn[i][0], e_in[0]), cmul(rn[i][1], e_in[1]));
        Cx apply_0 = cadd(cmul(r0[i][0], e_in[0]), cmul(r0[i][1], e_in[1]));
        Cx v = csub(csub(cmul(cadd(d[0], d[1]), e_in[i]), cmul(d[2], apply_n)), cmul(d[3], apply_0));
        comp[i] = cscale(v, -spread);
    }
    *out = combine(comp[0], phi_hat_o, comp[1], beta_hat_o);
    return true;
}

// `area_per_length_angle`: |∂p/∂φ × ∂p/∂ℓ|, the map area per metre of edge and radian of cone.
CUDA_CALLABLE double area_per_length_angle(const WedgeD& w, V3 src, double ell, V3 ko, V3 p, V3 n) {
    V3 e = w.e, n0 = w.n0;
    V3 t0 = vnormalize(vcross(n0, e));
    double along = vdot(vsub(src, w.a), e);
    double r = vlength(vsub(vsub(src, w.a), vmul(e, along)));
    double z = ell - along;
    double rho2 = r * r + z * z;
    double sin_t = r / dsqrt(rho2), cos_t = z / dsqrt(rho2);
    double phi = atan2_d(vdot(ko, n0), vdot(ko, t0));
    double sin_p, cos_p;
    sincos_d(phi, &sin_p, &cos_p);
    V3 dk_dphi = vmul(vsub(vmul(n0, cos_p), vmul(t0, sin_p)), sin_t);
    double dtheta_dell = -r / rho2;
    V3 dk_dell = vmul(vsub(vmul(vadd(vmul(t0, cos_p), vmul(n0, sin_p)), cos_t), vmul(e, sin_t)),
                      dtheta_dell);
    V3 q = vadd(w.a, vmul(e, ell));
    double t = vdot(vsub(p, q), ko);
    double nk = vdot(n, ko);
    if (abs_d(nk) < 1e-12) return 0.0;
    V3 a = vmul(dk_dphi, t);
    V3 b = vadd(e, vmul(dk_dell, t));
    V3 dp_dphi = vsub(a, vmul(ko, vdot(n, a) / nk));
    V3 dp_dell = vsub(b, vmul(ko, vdot(n, b) / nk));
    return vlength(vcross(dp_dphi, dp_dell));
}

// `RfScene::blocked` without foliage: a surface strictly between a and b (eps kept clear at
// each end).
CUDA_CALLABLE bool blocked(const Node* nodes, u32 n_nodes, const TriPacket* packets, V3 a, V3 b,
                           double eps) {
    V3 ab = vsub(b, a);
    double len = vlength(ab);
    if (len <= 2.0 * eps) return false;
    V3 d = vdiv(ab, len);
    float of[3] = {(float)a.x, (float)a.y, (float)a.z};
    float df[3] = {(float)d.x, (float)d.y, (float)d.z};
    return any_hit(nodes, n_nodes, packets, of, df, (float)eps, (float)(len - eps));
}

// `first_wall` without foliage: where o + t d first meets a surface before t_max (∞ if none).
CUDA_CALLABLE double first_wall(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                                const double* tri, V3 o, V3 d, double t_max) {
    double t;
    u32 h;
    if (!cast_between(nodes, n_nodes, packets, tri, o, d, LEG_EPS_M, t_max + LEG_EPS_M, &t, &h))
        return 1.0 / 0.0;
    return t;
}

// The wedge sample i draws: the first whose running length passes u (`partition_point`).
CUDA_CALLABLE u32 pick_wedge(const double* cdf, u32 n, double total, u32 i) {
    double u = unit01(mix64(DIFF_SALT ^ (u64)i)) * total;
    u32 lo = 0, hi = n;
    while (lo < hi) {
        u32 mid = lo + (hi - lo) / 2;
        if (cdf[mid] <= u)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < n - 1 ? lo : n - 1;
}

// The n-th crossing of the map's surface by q + t ko past `after` (the flat plane: one at
// most), as (t, cell, normal); false when there is none.
CUDA_CALLABLE bool next_crossing(const Surface& surface, const double* k, V3 q, V3 ko,
                                 double after, double* t_out, u32* cell, V3* normal) {
    if (surface.n_nodes == 0) {
        if (after > 0.0 || ko.z == 0.0) return false;
        double t = (k[C_Z] - q.z) / ko.z;
        if (!(t > EPS_M)) return false;
        if (!cell_index(k, q.x + ko.x * t, q.y + ko.y * t, cell)) return false;
        *t_out = t;
        *normal = v3(0.0, 0.0, 1.0);
        return true;
    }
    float of[3] = {(float)q.x, (float)q.y, (float)q.z};
    float df[3] = {(float)ko.x, (float)ko.y, (float)ko.z};
    double tmin = EPS_M;
    if (after > 0.0) {
        tmin = after + EPS_M;
        // Past 2^14 m an f32 step of EPS_M can round back onto the same hit.
        if (!((float)tmin > (float)after)) return false;
    }
    for (;;) {
        float ts;
        u32 sp;
        if (!closest_hit(surface.nodes, surface.n_nodes, surface.packets, of, df, (float)tmin,
                         3.40282347e38f, &ts, &sp))
            return false;
        double t = (double)ts;
        const float* nf = surface.normals + 3 * (u64)sp;
        if (cell_index(k, q.x + ko.x * t, q.y + ko.y * t, cell)) {
            *t_out = t;
            *normal = v3((double)nf[0], (double)nf[1], (double)nf[2]);
            return true;
        }
        // Off the grid: the next crossing.
        double next = t + EPS_M;
        if (!((float)next > ts)) return false;
        tmin = next;
    }
}

// Diffraction sample i of a map (`EdgeSampler::sample`): its wedge of `wedges`
// (WEDGE_WORDS f64 each, `cdf` their running lengths), drawn `drawn[w]` times in all.
CUDA_CALLABLE void diffract(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                            const double* tri, const u32* material, const double* slabs,
                            const Surface& surface, const double* k, const double* wedges,
                            const double* cdf, const u32* drawn, u32 i, u64* acc) {
    u32 n_wedges = (u32)k[C_WEDGES];
    u32 wi = pick_wedge(cdf, n_wedges, k[C_WEDGE_LEN], i);
    WedgeD w = wedge_at(wedges + (u64)wi * WEDGE_WORDS);
    u64 h = mix64(DIFF_SALT ^ ((u64)i * 0x9E3779B97F4A7C15ull));
    double u_edge = unit01(mix64(h ^ 1ull)), u_cone = unit01(mix64(h ^ 2ull));
    double weight = w.length / (double)drawn[wi];
    V3 tx = v3(k[C_TX], k[C_TX + 1], k[C_TX + 2]);
    double ell = u_edge * w.length;
    V3 q = vadd(w.a, vmul(w.e, ell));
    double s_in = vlength(vsub(q, tx));
    if (s_in <= MIN_LEG_M) return;
    V3 ki = vdiv(vsub(q, tx), s_in);
    double angle = w.n * PI_D;
    V3 ko = keller_cone(w, ki, u_cone * angle);
    // The last crossing first: most cone directions miss the map, at no cost through the scene.
    double last = 0.0, t;
    u32 cell;
    V3 normal;
    while (next_crossing(surface, k, q, ko, last, &t, &cell, &normal)) last = t;
    if (!(last > 0.0)) return;
    V3 q_out = vadd(q, vmul(vnormalize_or_zero(vadd(w.n0, w.nn)), OUTSIDE_CORNER_M));
    if (blocked(nodes, n_nodes, packets, tx, q, LEG_EPS_M) ||
        blocked(nodes, n_nodes, packets, tx, q_out, LEG_EPS_M))
        return;
    double t_end = min_d(first_wall(nodes, n_nodes, packets, tri, q, ko, last),
                         first_wall(nodes, n_nodes, packets, tri, q_out, ko, last));
    Field e_tx = antenna_field(k, ki);
    double after = 0.0;
    while (next_crossing(surface, k, q, ko, after, &t, &cell, &normal)) {
        after = t;
        if (t <= MIN_LEG_M || t >= t_end) continue;
        V3 p = vadd(q, vmul(ko, t));
        Field e;
        if (!diffracted_field(slabs, material, k, w, q, tx, p, e_tx, &e)) continue;
        double area = area_per_length_angle(w, tx, ell, ko, p, normal);
        double nz = abs_d(normal.z);
        double patch = k[C_CELL] * k[C_CELL] / (nz > 1e-6 ? nz : 1e-6);
        accumulate(acc, cell, field_norm2(e) * area * angle * weight / patch);
    }
}

#ifdef KODAMA_DEVICE
extern "C" __global__ void kodama_cast(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                                       const float* rays, u64 n, float* t_out, u32* prim_out) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) cast_one(nodes, n_nodes, packets, rays, i, t_out, prim_out);
}

extern "C" __global__ void kodama_occluded(const Node* nodes, u32 n_nodes,
                                           const TriPacket* packets, const float* rays, u64 n,
                                           u8* out) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) occluded_one(nodes, n_nodes, packets, rays, i, out);
}

// Thread i shoots the lattice's `order[i]`-th ray: the lattice's patch order, so a warp's rays
// leave side by side and walk the same nodes.
// `seen` (a byte per triangle) gets the triangles rays first land on; null without diffraction.
extern "C" __global__ void kodama_map(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                                      const double* tri, const u32* material, const double* slabs,
                                      const Node* s_nodes, u32 s_n_nodes,
                                      const TriPacket* s_packets, const float* s_normals,
                                      const double* consts, const u32* order, u64 n, u64* acc,
                                      u8* seen) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    Surface surface = {s_nodes, s_n_nodes, s_packets, s_normals};
    if (i < n)
        shoot(nodes, n_nodes, packets, tri, material, slabs, surface, consts, order[i], acc,
              seen);
}

// Thread i counts diffraction sample i in its wedge's `drawn`.
extern "C" __global__ void kodama_draws(const double* consts, const double* cdf, u64 n,
                                        u32* drawn) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) atomicAdd(&drawn[pick_wedge(cdf, (u32)consts[C_WEDGES], consts[C_WEDGE_LEN], (u32)i)], 1u);
}

// Thread i adds diffraction sample i to the map.
extern "C" __global__ void kodama_diffraction(const Node* nodes, u32 n_nodes,
                                              const TriPacket* packets, const double* tri,
                                              const u32* material, const double* slabs,
                                              const Node* s_nodes, u32 s_n_nodes,
                                              const TriPacket* s_packets, const float* s_normals,
                                              const double* consts, const double* wedges,
                                              const double* cdf, const u32* drawn, u64 n,
                                              u64* acc) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    Surface surface = {s_nodes, s_n_nodes, s_packets, s_normals};
    if (i < n)
        diffract(nodes, n_nodes, packets, tri, material, slabs, surface, consts, wedges, cdf,
                 drawn, (u32)i, acc);
}

// Thread i searches from the lattice's `order[i]`-th ray (the patch order: a warp's rays leave
// side by side).
extern "C" __global__ void kodama_sequences(const Node* nodes, u32 n_nodes,
                                            const TriPacket* packets, const double* tri,
                                            const u32* material, const double* consts,
                                            const u32* order, u64 n, u32* slots, u32 slot_mask,
                                            u32* seqs, u32 stride, u32 seq_cap, u32* counters) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    SeqSet set = {slots, slot_mask, seqs, stride, seq_cap, counters};
    if (i < n && load_word(&counters[1]) == 0)
        search(nodes, n_nodes, packets, tri, material, consts, order[i], set);
}

// Block c orders rays c * chunk.. of an n-ray lattice (chunk at most ORDER_CHUNK, ORDER_THREADS
// threads a block) into order[c * chunk..] as lattice indices; `scratch` holds chunk / 4 + 2
// words a block.
extern "C" __global__ void kodama_order(u32 n, u32 chunk, u32* order, u32* scratch) {
    __shared__ u32 row_start[ORDER_ROWS];
    __shared__ u32 bin_off[ORDER_ROWS];
    __shared__ u32 partial[ORDER_THREADS];
    __shared__ u32 rows;
    u32 start = blockIdx.x * chunk;
    u32 tid = threadIdx.x, threads = blockDim.x;
    if (start >= n) return;
    u32 len = n - start < chunk ? n - start : chunk;
    if (tid == 0) rows = patch_rows(n, start, len, row_start, bin_off);
    __syncthreads();
    OrderChunk c;
    c.n = n;
    c.start = start;
    c.len = len;
    c.rows = rows;
    c.base = start;
    c.row_start = row_start;
    c.bin_off = bin_off;
    c.count = scratch + (u64)blockIdx.x * (chunk / 4 + 2);
    c.partial = partial;
    c.out = order + start;
    order_zero(c, tid, threads);
    __syncthreads();
    order_histogram(c, tid, threads);
    __syncthreads();
    order_scan_segment(c, tid, threads);
    __syncthreads();
    if (tid == 0) order_scan_totals(c, threads);
    __syncthreads();
    order_scan_add(c, tid, threads);
    __syncthreads();
    order_scatter(c, tid, threads);
    __syncthreads();
    order_sort_bins(c, tid, threads);
}
#else
// The host twin of `kodama_cast` (nodes/build.rs compiles it under feature `cuda`).
extern "C" void kodama_host_cast(const void* nodes, u32 n_nodes, const void* packets,
                                 const float* rays, u64 n, float* t_out, u32* prim_out) {
    for (u64 i = 0; i < n; i++)
        cast_one((const Node*)nodes, n_nodes, (const TriPacket*)packets, rays, i, t_out,
                 prim_out);
}

// The host twin of `kodama_occluded`.
extern "C" void kodama_host_occluded(const void* nodes, u32 n_nodes, const void* packets,
                                     const float* rays, u64 n, u8* out) {
    for (u64 i = 0; i < n; i++)
        occluded_one((const Node*)nodes, n_nodes, (const TriPacket*)packets, rays, i, out);
}

// The host twin of `kodama_map`: rays `first..first + n` of the lattice (any order gives the
// same integer sums).
extern "C" void kodama_host_map(const void* nodes, u32 n_nodes, const void* packets,
                                const double* tri, const u32* material, const double* slabs,
                                const void* s_nodes, u32 s_n_nodes, const void* s_packets,
                                const float* s_normals, const double* consts, u32 first, u64 n,
                                u64* acc, u8* seen) {
    Surface surface = {(const Node*)s_nodes, s_n_nodes, (const TriPacket*)s_packets, s_normals};
    for (u64 i = 0; i < n; i++)
        shoot((const Node*)nodes, n_nodes, (const TriPacket*)packets, tri, material, slabs,
              surface, consts, first + (u32)i, acc, seen);
}

// The host twin of `kodama_draws`, samples 0..n.
extern "C" void kodama_host_draws(const double* consts, const double* cdf, u64 n, u32* drawn) {
    for (u64 i = 0; i < n; i++)
        drawn[pick_wedge(cdf, (u32)consts[C_WEDGES], consts[C_WEDGE_LEN], (u32)i)]++;
}

// The host twin of `kodama_diffraction`: samples first..first + n.
extern "C" void kodama_host_diffraction(const void* nodes, u32 n_nodes, const void* packets,
                                        const double* tri, const u32* material,
                                        const double* slabs, const void* s_nodes, u32 s_n_nodes,
                                        const void* s_packets, const float* s_normals,
                                        const double* consts, const double* wedges,
                                        const double* cdf, const u32* drawn, u32 first, u64 n,
                                        u64* acc) {
    Surface surface = {(const Node*)s_nodes, s_n_nodes, (const TriPacket*)s_packets, s_normals};
    for (u64 i = 0; i < n; i++)
        diffract((const Node*)nodes, n_nodes, (const TriPacket*)packets, tri, material, slabs,
                 surface, consts, wedges, cdf, drawn, first + (u32)i, acc);
}
// The host twin of `kodama_sequences`: rays `first..first + n` of the lattice into one set.
extern "C" void kodama_host_sequences(const void* nodes, u32 n_nodes, const void* packets,
                                      const double* tri, const u32* material,
                                      const double* consts, u32 first, u64 n, u32* slots,
                                      u32 slot_mask, u32* seqs, u32 stride, u32 seq_cap,
                                      u32* counters) {
    SeqSet set = {slots, slot_mask, seqs, stride, seq_cap, counters};
    for (u64 i = 0; i < n && counters[1] == 0; i++)
        search((const Node*)nodes, n_nodes, (const TriPacket*)packets, tri, material, consts,
               first + (u32)i, set);
}
// The host twin of `kodama_order` for one chunk, rays `start..start + len` of an n-ray lattice
// (len at most ORDER_CHUNK and within n), as offsets from start: the device's phases, run one
// thread after another.
extern "C" void kodama_host_order(u32 n, u32 start, u32 len, u32* out) {
    u32* row_start = new u32[ORDER_ROWS];
    u32* bin_off = new u32[ORDER_ROWS];
    u32* count = new u32[len / 4 + 2];
    u32* partial = new u32[ORDER_THREADS];
    OrderChunk c;
    c.n = n;
    c.start = start;
    c.len = len;
    c.rows = patch_rows(n, start, len, row_start, bin_off);
    c.base = 0;
    c.row_start = row_start;
    c.bin_off = bin_off;
    c.count = count;
    c.partial = partial;
    c.out = out;
    const u32 T = ORDER_THREADS;
    for (u32 t = 0; t < T; t++) order_zero(c, t, T);
    for (u32 t = 0; t < T; t++) order_histogram(c, t, T);
    for (u32 t = 0; t < T; t++) order_scan_segment(c, t, T);
    order_scan_totals(c, T);
    for (u32 t = 0; t < T; t++) order_scan_add(c, t, T);
    for (u32 t = 0; t < T; t++) order_scatter(c, t, T);
    for (u32 t = 0; t < T; t++) order_sort_bins(c, t, T);
    delete[] row_start;
    delete[] bin_off;
    delete[] count;
    delete[] partial;
}
#endif
