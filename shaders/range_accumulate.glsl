#version 430 core
// Pass 2: add every (row, column) sample's weight into its (ping, range bin) cell.
// Fixed-point weights with 32-bit atomicAdd on a low word and a carry into a high word:
// integer addition is exact and does not depend on order, so the image is deterministic.
// Defines: SPLIT (0 nearest: whole weight to the bin holding the centre range; 1 linear:
// split between the two nearest bin centres; 2 footprint: spread uniformly over the range
// interval the sample's ray bundle covers, at most MAX_SPREAD bins).

#ifndef SPLIT
#error "SPLIT must be defined"
#endif
#define MAX_SPREAD 16

#if defined COMPUTE_SHADER
layout(local_size_x = 64, local_size_y = 4) in;
layout(binding = 0) uniform sampler2D samples;
layout(std430, binding = 1) buffer Cells { uint cells[]; };   // (ping, bin, {lo, hi})
uniform ivec2 size;             // framebuffer width (columns), height (rows)
uniform int rows_per_ping;
uniform int ping_offset;        // first ping of this segment in the accumulator
uniform int n_bins;
uniform float inv_bin;          // 1 / range bin (1/m)
uniform float scale;            // fixed-point units per weight unit

void deposit(int ping, int bin, float w) {
    if (bin < 0 || bin >= n_bins) return;
    uint v = uint(w * scale + 0.5);
    if (v == 0u) return;
    uint idx = 2u * uint(ping * n_bins + bin);
    uint old = atomicAdd(cells[idx], v);
    if (old > 0xFFFFFFFFu - v) atomicAdd(cells[idx + 1u], 1u);
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= size.x || p.y >= size.y) return;
    vec4 s = texelFetch(samples, p, 0);
    float w = s.z;
    if (!(w > 0.0)) return;
    int ping = ping_offset + p.y / rows_per_ping;
#if SPLIT == 2
    float a = s.x * inv_bin, b = s.y * inv_bin;
    float mid = 0.5 * (a + b);
    float half_width = min(0.5 * (b - a), 0.5 * float(MAX_SPREAD - 1));
    a = mid - half_width;
    b = mid + half_width;
    if (b - a < 1e-4) {
        deposit(ping, int(floor(mid)), w);
        return;
    }
    float inv = w / (b - a);
    for (int k = int(floor(a)); float(k) < b; ++k) {
        float overlap = min(b, float(k + 1)) - max(a, float(k));
        deposit(ping, k, overlap * inv);
    }
#elif SPLIT == 1
    float f = 0.5 * (s.x + s.y) * inv_bin - 0.5;
    float c = floor(f);
    float t = f - c;
    deposit(ping, int(c), w * (1.0 - t));
    deposit(ping, int(c) + 1, w * t);
#else
    deposit(ping, int(floor(0.5 * (s.x + s.y) * inv_bin)), w);
#endif
}
#endif
