#version 430 core
// Pass 2: add every (row, column) sample's weight into its (ping, range bin) cell.
// Fixed-point weights with 32-bit atomicAdd on a low word and a carry into a high word:
// integer addition is exact and does not depend on order, so the image is deterministic.
// Defines: SPLIT (0 nearest: whole weight to the bin holding the centre range; 1 linear:
// split between the two nearest bin centres; 2 footprint: spread uniformly over the range
// interval the sample's ray bundle covers, at most MAX_SPREAD bins); LABELS (1: also keep,
// per cell, the label of the sample whose share of the cell is largest).

#ifndef SPLIT
#error "SPLIT must be defined"
#endif
#ifndef LABELS
#error "LABELS must be defined"
#endif
#define MAX_SPREAD 16

#if defined COMPUTE_SHADER
layout(local_size_x = 64, local_size_y = 4) in;
layout(binding = 0) uniform sampler2D samples;
uniform sampler2D depth;        // pass 1's depth: 1 where no fragment landed (colour is stale)
layout(std430, binding = 1) buffer Cells { uint cells[]; };   // (ping, bin, {lo, hi})
uniform ivec2 size;             // framebuffer width (columns), height (rows)
uniform int rows_per_ping;
uniform int ping_offset;        // first ping of this segment in the accumulator
uniform int n_bins;
uniform float inv_bin;          // 1 / range bin (1/m)
uniform float scale;            // fixed-point units per weight unit
#if LABELS
uniform usampler2D sample_labels;  // pass 1's label target: object id + 1 per texel
layout(std430, binding = 3) buffer CellLabels { uint cell_labels[]; };   // (ping, bin)
uint label;
#endif

void deposit(int ping, int bin, float w) {
    if (bin < 0 || bin >= n_bins) return;
#if LABELS
    // The bits of a positive float order like its value: the top 16 (sign, exponent, 7
    // mantissa bits) rank the share to 1 %, the low 16 carry the label; the max wins.
    if (w > 0.0) {
        uint key = (floatBitsToUint(w) & 0xFFFF0000u) | (label & 0xFFFFu);
        atomicMax(cell_labels[uint(ping * n_bins + bin)], key);
    }
#endif
    uint v = uint(min(w * scale, 2147483648.0) + 0.5);  // the scale keeps it below 2^31
    if (v == 0u) return;
    uint idx = 2u * uint(ping * n_bins + bin);
    uint old = atomicAdd(cells[idx], v);
    if (old > 0xFFFFFFFFu - v) atomicAdd(cells[idx + 1u], 1u);
}

// Cumulative share of a sample below s (in bins, relative to the patch's lower end) for the
// sum of two uniform spreads of widths wa >= wb (a trapezoid density of total width wa + wb).
float trapezoid_cdf(float s, float wa, float wb) {
    if (s <= 0.0) return 0.0;
    if (s >= wa + wb) return 1.0;
    if (wb < 1e-6) return s / wa;
    if (s < wb) return s * s / (2.0 * wa * wb);
    if (s <= wa) return (s - 0.5 * wb) / wa;
    float u = wa + wb - s;
    return 1.0 - u * u / (2.0 * wa * wb);
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= size.x || p.y >= size.y) return;
    if (texelFetch(depth, p, 0).r >= 1.0) return;
    vec4 s = texelFetch(samples, p, 0);
    float w = s.w;
    if (!(w > 0.0)) return;
    int ping = ping_offset + p.y / rows_per_ping;
#if LABELS
    label = texelFetch(sample_labels, p, 0).r;
#endif
    float centre = s.x * inv_bin;
#if SPLIT == 2
    float wa = max(s.y, s.z) * inv_bin, wb = min(s.y, s.z) * inv_bin;
    float total = wa + wb;
    if (total > float(MAX_SPREAD - 1)) {      // grazing: keep the shape, bound the spread
        float k = float(MAX_SPREAD - 1) / total;
        wa *= k;
        wb *= k;
        total = wa + wb;
    }
    if (total < 1e-4) {
        deposit(ping, int(floor(centre)), w);
        return;
    }
    float lo = centre - 0.5 * total;
    int first = int(floor(lo));
    float before = 0.0;
    for (int k = first; float(k) < lo + total; ++k) {
        float after = trapezoid_cdf(float(k + 1) - lo, wa, wb);
        deposit(ping, k, w * (after - before));
        before = after;
    }
#elif SPLIT == 1
    float f = centre - 0.5;
    float c = floor(f);
    float t = f - c;
    deposit(ping, int(c), w * (1.0 - t));
    deposit(ping, int(c) + 1, w * t);
#else
    deposit(ping, int(floor(centre)), w);
#endif
}
#endif
