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

// `SceneRays::cast_index`: the closest (t, triangle) of `o + t d`, t in (tmin, tmax); returns
// false on a miss. `d` need not be canonical: -0.0 is made +0.0 first, as the CPU does.
CUDA_CALLABLE bool closest_hit(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                               const float o_in[3], const float d_in[3], float tmin, float tmax,
                               float* t_out, u32* prim_out) {
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

#ifdef KODAMA_DEVICE
extern "C" __global__ void kodama_cast(const Node* nodes, u32 n_nodes, const TriPacket* packets,
                                       const float* rays, u64 n, float* t_out, u32* prim_out) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i < n) cast_one(nodes, n_nodes, packets, rays, i, t_out, prim_out);
}
#else
// The host twin of `kodama_cast` (nodes/build.rs compiles it under feature `cuda`).
extern "C" void kodama_host_cast(const void* nodes, u32 n_nodes, const void* packets,
                                 const float* rays, u64 n, float* t_out, u32* prim_out) {
    for (u64 i = 0; i < n; i++)
        cast_one((const Node*)nodes, n_nodes, (const TriPacket*)packets, rays, i, t_out,
                 prim_out);
}
#endif
