#version 430 core
// Pass 2: add every (row, column) sample's weight into its (ping, range bin) cell.
// Fixed-point weights with 32-bit atomicAdd on a low word and a carry into a high word:
// integer addition is exact and does not depend on order, so the image is deterministic.
// Defines: SPLIT (0 nearest: whole weight to the bin holding the centre range; 1 linear:
// split between the two nearest bin centres; 2 footprint: spread uniformly over the range
// interval the sample's ray bundle covers, at most MAX_SPREAD bins); LABELS (1: also keep,
// per cell, the label of the sample whose share of the cell is largest); SWEEP (0: one
// invocation per pass-1 texel; 1: the heightfield sweep below, one invocation per row, which
// finds each ray's first hit on a seabed grid itself and merges it with pass 1's texel of
// the other objects); SCATTERING (as in ping_samples.glsl; used by the sweep).

#ifndef SPLIT
#error "SPLIT must be defined"
#endif
#ifndef LABELS
#error "LABELS must be defined"
#endif
#ifndef SWEEP
#error "SWEEP must be defined"
#endif
#ifndef SCATTERING
#error "SCATTERING must be defined"
#endif
#if SWEEP && !defined SWEEP_GROUP
#error "SWEEP_GROUP (rows per workgroup) must be defined for the sweep"
#endif
#define MAX_SPREAD 16

#if defined COMPUTE_SHADER
#if SWEEP
layout(local_size_x = SWEEP_GROUP) in;
#else
layout(local_size_x = 64, local_size_y = 4) in;
#endif
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

// Add v (and hi carries) to cell (ping, bin) with the exact two-word atomics.
void cell_add(int ping, int bin, uint v, uint hi) {
    uint idx = 2u * uint(ping * n_bins + bin);
    uint old = atomicAdd(cells[idx], v);
    if (old > 0xFFFFFFFFu - v) hi += 1u;
    if (hi != 0u) atomicAdd(cells[idx + 1u], hi);
}

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
    cell_add(ping, bin, v, 0u);
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

// Share sample s = (centre range, look-angle spread, along-track spread, weight) of `ping`.
void accumulate(int ping, vec4 s) {
    float w = s.w;
    if (!(w > 0.0)) return;
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

#if !SWEEP
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= size.x || p.y >= size.y) return;
    if (texelFetch(depth, p, 0).r >= 1.0) return;
    vec4 s = texelFetch(samples, p, 0);
    if (!(s.w > 0.0)) return;
#if LABELS
    label = texelFetch(sample_labels, p, 0).r;
#endif
    accumulate(ping_offset + p.y / rows_per_ping, s);
}
#else
// ---- the heightfield sweep (SWEEP 1) ------------------------------------------------------
// One invocation per row of a level fan (its up axis vertical): the fan's trace on the plane is
// the straight line o + s side (s >= 0), which a walk through the grid's cells (and across each
// cell's diagonal) cuts into pieces, each inside one triangle. Walking outward, the surface
// point at the end of a piece is above or on the ray at depression a when
// s sin(a) + v cos(a) >= 0 (v: height above the ray's origin); the first piece whose end is,
// holds the ray's first hit, and rays are taken in column order (depression decreasing), so
// every piece and every column is visited once. The sample is computed from the triangle's
// plane exactly as ping_samples.glsl's fragment shader does.
layout(std430, binding = 4) readonly buffer Positions { float pos[]; };    // xyz per vertex (the VBO)
layout(std430, binding = 5) readonly buffer GridFaces { vec2 grid_face[]; };  // (R, law), grid order
// Per column of the whole draw: (cos a, sin a, Phi da, da / 2).
layout(std430, binding = 6) readonly buffer ColumnTrig { vec4 col_trig[]; };
uniform ivec2 grid_n;           // nodes along i and j
uniform int grid_v0;            // vertex index of node (0, 0)
uniform vec2 grid_origin;       // node (0, 0), local metres
uniform mat2 grid_inverse;      // horizontal offset (metres) to grid units (i, j)
uniform float grid_winding;     // 1, or -1 for faces with their corners reversed
uniform vec3 seg_origin;        // as in ping_samples.glsl
uniform vec3 axis_along;
uniform vec3 axis_side;
uniform vec3 axis_up;
uniform vec3 motion;
uniform vec3 travel;            // direction of travel, local (world) axes
uniform float frame_sign;
uniform float spacing;
uniform float row_width;
uniform float far_range;
uniform int col_first;          // first column of this tile in the draw's column list
uniform int col_begin;          // first column (of the tile) of this dispatch
uniform int chunk;              // columns per dispatch
layout(std430, binding = 7) buffer WalkState { vec4 walk_state[]; };   // 2 per row
uniform float s_stop;           // walk no farther along the trace, metres
uniform int has_raster;         // 1: pass 1 drew other objects into samples / depth
uniform uint grid_label;        // label of the grid's faces (object id + 1)
#if SCATTERING == 2
uniform sampler2D laws;
#endif

float scattering_over_cos(float cos_t, int law) {
#if SCATTERING == 1
    return 1.0;
#else
    // As ping_samples.glsl (keep the two in step): linear in incidence angle between the two
    // nearest table samples.
    int n = textureSize(laws, 0).x;
    float x = acos(clamp(cos_t, 0.0, 1.0)) / 1.5707963267948966 * float(n - 1);
    int j = clamp(int(floor(x)), 0, n - 2);
    float a = texelFetch(laws, ivec2(j, law), 0).r;
    float b = texelFetch(laws, ivec2(j + 1, law), 0).r;
    return mix(a, b, x - float(j));
#endif
}

vec3 node(int i, int j) {
    int k = 3 * (grid_v0 + j * grid_n.x + i);
    return vec3(pos[k], pos[k + 1], pos[k + 2]);
}

vec3 fan(vec3 p) {
    vec3 d = p - seg_origin;
    return vec3(dot(d, axis_along), dot(d, axis_side), dot(d, axis_up));
}

float plane_hit(vec4 pl, vec3 origin, float c, float s) {
    float denom = pl.y * c - pl.z * s;
    return denom < -1e-9 ? (pl.w - dot(pl.xyz, origin)) / denom : -1.0;
}

// Emit column c (tile-local) of row `row`: the grid's sample (if hit) or pass 1's, the nearer.
void emit(int c, int row, int ping, bool hit, vec4 smp, float t_hit) {
    uint lab = grid_label;
    if (has_raster == 1) {
        ivec2 p = ivec2(c, row);
        float d = texelFetch(depth, p, 0).r;
        if (d < 1.0 && (!hit || d <= t_hit / far_range)) {
            smp = texelFetch(samples, p, 0);
            hit = true;
#if LABELS
            lab = texelFetch(sample_labels, p, 0).r;
#endif
        }
    }
    if (!hit) return;
#if LABELS
    label = lab;
#endif
    accumulate(ping, smp);
}

// The walk's state along one row's trace: the next unresolved column and its table entry, the
// start of the next piece (s along the trace, v height above the ray origin).
struct Walk {
    int c;
    int c_end;
    vec4 trig;
    float s0;
    float v0;
};

// One piece of the trace, from w.s0 to s1 (height v1 there) inside the triangle (pa, p1, p2)
// (face `face` of the grid): resolve every column whose ray passes below the piece's end.
void piece(inout Walk w, float s1, float v1, vec3 pa, vec3 p1, vec3 p2, int face, int row,
           int ping, vec3 q_o) {
    if (w.c < w.c_end && s1 * w.trig.y + v1 * w.trig.x >= 0.0) {
        // The plane of the piece's triangle, in fan coordinates (as the geometry shader).
        vec3 q0 = fan(pa), q1 = fan(p1), q2 = fan(p2);
        vec3 n = frame_sign * grid_winding * cross(q1 - q0, q2 - q0);
        n /= length(n);
        vec4 pl = vec4(n, dot(n, q0));
        vec2 fd = grid_face[face];
        while (w.c < w.c_end && s1 * w.trig.y + v1 * w.trig.x >= 0.0) {
            float ca = w.trig.x, sa = w.trig.y;
            // cos and sin of the column's half width (at most a few degrees: 3 terms each)
            float h = w.trig.w, h2 = h * h;
            float ch = 1.0 - h2 * (0.5 - h2 / 24.0), sh = h * (1.0 - h2 * (1.0 / 6.0 - h2 / 120.0));
            vec4 edges = vec4(ca * ch + sa * sh, sa * ch - ca * sh, ca * ch - sa * sh, sa * ch + ca * sh);
            float cos_t = -(n.y * ca - n.z * sa);
            float t = plane_hit(pl, q_o, ca, sa);
            if (!(t > 0.0)) {                  // grazing: where the ray crosses the piece
                float g0 = w.s0 * sa + w.v0 * ca, g1 = s1 * sa + v1 * ca;
                float lam = g0 < 0.0 ? g0 / (g0 - g1) : 0.0;
                t = length(vec2(mix(w.s0, s1, lam), mix(w.v0, v1, lam)));
            }
            vec4 smp = vec4(t, 0.0, 0.0, 0.0);
            if (cos_t > 0.0) {
                float ta = plane_hit(pl, q_o, edges.x, edges.y);
                float tb = plane_hit(pl, q_o, edges.z, edges.w);
                float lo = min(t, min(ta > 0.0 ? ta : t, tb > 0.0 ? tb : t));
                float hi = max(t, max(ta, tb));
                float along = abs(dot(n, motion) / cos_t) * row_width;
                float wt = fd.x * scattering_over_cos(cos_t, int(fd.y + 0.5)) * t * w.trig.z
                           * row_width * motion.x;
                smp = vec4(0.5 * (lo + hi), hi - lo, along, wt);
            }
            emit(w.c, row, ping, true, smp, t);
            ++w.c;
            if (w.c < w.c_end) w.trig = col_trig[col_first + w.c];
        }
    }
    w.s0 = s1;
    w.v0 = v1;
}

// Height of the triangle (a, b, c) (lower) or (a, c, d) of a cell at cell coordinates f.
float cell_height(bool lower, vec2 f, float za, float zb, float zc, float zd) {
    f = clamp(f, 0.0, 1.0);
    return lower ? za + f.x * (zb - za) + f.y * (zc - zb) : za + f.y * (zd - za) + f.x * (zc - zd);
}

// One invocation per row and a run of `chunk` columns from `col_begin`. llvmpipe ends a
// shader invocation's loops after 65535 iterations in all, so a row is swept in several
// dispatches, each resuming the walk where the previous one stopped (WalkState), at the start
// of the cell that resolved its last column: the next columns' hits lie in that cell or beyond.
void main() {
    int row = int(gl_GlobalInvocationID.x);
    if (row >= size.y) return;
    Walk w;
    w.c = col_begin;
    w.c_end = min(col_begin + chunk, size.x);
    int ping = ping_offset + row / rows_per_ping;
    float y = ((float(row) + 0.5) / float(rows_per_ping) - 0.5) * spacing;
    vec3 q_o = y * motion;                       // the ray origin in fan coordinates
    vec3 o = seg_origin + y * travel;            // and in local coordinates
    vec2 g = grid_inverse * (o.xy - grid_origin);   // grid coordinates of the origin
    vec2 e = grid_inverse * axis_side.xy;           // grid units per metre along the trace
    int di = e.x > 0.0 ? 1 : -1, dj = e.y > 0.0 ? 1 : -1;
    float step_x = e.x != 0.0 ? abs(1.0 / e.x) : 1e30;
    float step_y = e.y != 0.0 ? abs(1.0 / e.y) : 1e30;
    int i, j;
    float sx, sy;
    bool first = col_begin == 0, done = false;
    if (first) {
        i = clamp(int(floor(g.x)), 0, grid_n.x - 2);
        j = clamp(int(floor(g.y)), 0, grid_n.y - 2);
        sx = e.x > 0.0 ? (float(i + 1) - g.x) / e.x : (e.x < 0.0 ? (float(i) - g.x) / e.x : 1e30);
        sy = e.y > 0.0 ? (float(j + 1) - g.y) / e.y : (e.y < 0.0 ? (float(j) - g.y) / e.y : 1e30);
        w.s0 = 0.0;
        w.v0 = 0.0;
    } else {
        vec4 a = walk_state[2 * row], b = walk_state[2 * row + 1];
        i = floatBitsToInt(a.x);
        j = floatBitsToInt(a.y);
        sx = a.z;
        sy = a.w;
        w.s0 = b.x;
        w.v0 = b.y;
        done = b.z != 0.0;
    }
    w.trig = col_trig[col_first + w.c];
    while (!done && w.c < w.c_end) {
        vec4 cell_a = vec4(intBitsToFloat(i), intBitsToFloat(j), sx, sy);
        vec2 cell_b = vec2(w.s0, w.v0);
        float s_end = min(min(sx, sy), s_stop);
        vec3 pa = node(i, j), pb = node(i + 1, j), pc = node(i + 1, j + 1), pd = node(i, j + 1);
        // The cell's diagonal (from node (i, j) to (i + 1, j + 1)) splits the walk in the cell.
        float f0 = (g.x - float(i)) - (g.y - float(j));   // fx - fy at s = 0
        float df = e.x - e.y;
        float s_diag = df != 0.0 ? -f0 / df : -1.0;
        bool split = s_diag > w.s0 && s_diag < s_end;
        float s1 = split ? s_diag : s_end;
        bool lower = f0 + df * 0.5 * (w.s0 + s1) >= 0.0;   // fx >= fy: (a, b, c), else (a, c, d)
        vec2 base = g - vec2(float(i), float(j));
        if (first) {
            w.v0 = cell_height(lower, base, pa.z, pb.z, pc.z, pd.z) - o.z;
            cell_b.y = w.v0;
            first = false;
        }
        int face = 2 * (j * (grid_n.x - 1) + i);
        float v1 = cell_height(lower, base + e * s1, pa.z, pb.z, pc.z, pd.z) - o.z;
        piece(w, s1, v1, pa, lower ? pb : pc, lower ? pc : pd, face + (lower ? 0 : 1), row, ping,
              q_o);
        if (split) {
            float v2 = cell_height(!lower, base + e * s_end, pa.z, pb.z, pc.z, pd.z) - o.z;
            piece(w, s_end, v2, pa, lower ? pc : pb, lower ? pd : pc, face + (lower ? 1 : 0), row,
                  ping, q_o);
        }
        if (w.c >= w.c_end) {          // this run is resolved: the next resumes at this cell
            if (w.c_end < size.x) {
                walk_state[2 * row] = cell_a;
                walk_state[2 * row + 1] = vec4(cell_b, 0.0, 0.0);
            }
            return;
        }
        if (s_end >= s_stop) break;
        if (sx < sy) {
            i += di;
            sx += step_x;
        } else {
            j += dj;
            sy += step_y;
        }
        if (i < 0 || i > grid_n.x - 2 || j < 0 || j > grid_n.y - 2) break;
    }
    if (w.c_end < size.x) walk_state[2 * row + 1] = vec4(0.0, 0.0, 1.0, 0.0);   // walk over
    if (has_raster == 1) {
        for (; w.c < w.c_end; ++w.c) emit(w.c, row, ping, false, vec4(0.0), 0.0);
    }
}
#endif  // SWEEP
#endif  // COMPUTE_SHADER
