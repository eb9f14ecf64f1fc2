#version 430 core
// Pass 1: rasterise the scene for one straight track segment and one side into
// (ping row x look-angle column) samples. Each fragment is one ray of the fan:
// it writes the exact slant range of its hit and the weight Phi * R * f(cos t)/cos t * r * dalpha * dy.
// Defines: SCATTERING (1 = Lambert for every face; 2 = per-face law: row `law` of the `laws`
// table, f(t)/cos t sampled uniformly in incidence angle t from 0 to pi/2, row 0 = Lambert);
// LABELS (1: also write the face's label, object id + 1, to a second target for the label
// pass; 0: no label work at all).

#ifndef SCATTERING
#error "SCATTERING must be defined"
#endif
#ifndef LABELS
#error "LABELS must be defined"
#endif

#if defined VERTEX_SHADER
// Per vertex (shared by the triangles around it): segment-frame coordinates, look angle and
// the clip position (column from the warped angle, row from the along-track position, depth
// from the slant range).
in vec3 in_pos;                 // local coordinates (metres, scene local origin subtracted)
uniform vec3 seg_origin;        // segment origin, local coordinates
uniform vec3 axis_along;        // the fan's normal (the vehicle's fore axis)
uniform vec3 axis_side;         // starboard or port unit vector, in the fan plane
uniform vec3 axis_up;           // up, in the fan plane
uniform vec3 motion;            // unit direction of travel in (fore, side, up) coordinates
uniform float warp_h;           // nominal altitude of the range warp, metres
uniform float warp_c;           // near-nadir floor of the warp slope (fraction of warp_h)
uniform float alpha0;           // asin(warp_h / max_range): where the linear extension starts
uniform float rho0;             // warp value at alpha0
uniform float slope0;           // -d(warp)/d(alpha) at alpha0
uniform float rho_lo;           // warp value at the first column edge (alpha_max)
uniform float rho_hi;           // warp value at the last column edge (alpha_min)
uniform float row_scale;        // 2 / (spacing * pings)  (clip units per metre along track)
uniform float row_offset;       // clip y of along-track coordinate 0
uniform float far_range;        // slant range mapped to depth 1
out vec3 v_q;                   // (fore, side, up) coordinates relative to the segment origin
out float v_alpha;              // depression angle in (-pi/2, 3pi/2]

float warp(float a) {
    // Pseudo slant range: h / sin(a) + c h (pi/2 - a) between alpha0 and nadir, continued
    // linearly on both sides so it keeps decreasing (beyond nadir lies the other side).
    const float half_pi = 1.5707963267948966;
    if (a > half_pi) return warp_h - (a - half_pi) * (warp_c + 1.0) * warp_h;
    if (a >= alpha0) return warp_h / sin(a) + warp_c * warp_h * (half_pi - a);
    return rho0 + (alpha0 - a) * slope0;
}

void main() {
    vec3 d = in_pos - seg_origin;
    vec3 q = vec3(dot(d, axis_along), dot(d, axis_side), dot(d, axis_up));
    // The vertex lies in the fan of the ping at travel u; f is its offset from that ping, in
    // the fan plane (f.x = 0). Without crab or pitch, motion = (1, 0, 0) and f = (0, q.yz).
    float u = q.x / motion.x;
    vec3 f = q - u * motion;
    // The wrap of the angle is straight up, outside any beam.
    float a = atan(-f.z, f.y);
    if (a < -1.5707963267948966) a += 6.283185307179586;
    v_q = q;
    v_alpha = a;
    gl_Position = vec4(2.0 * (warp(a) - rho_lo) / (rho_hi - rho_lo) - 1.0,
                       u * row_scale + row_offset,
                       2.0 * length(f.yz) / far_range - 1.0, 1.0);
}
#endif

#if defined GEOMETRY_SHADER
// Per triangle: the plane (exact normal from the corners), the face's reflectivity, and the
// cull of triangles that wrap around the sonar.
layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;
in vec3 v_q[];
in float v_alpha[];
uniform float alpha_span_max;   // more angle than this (pi) means the triangle wraps over the top
uniform float frame_sign;       // det of the (along, side, up) frame: fixes the normal's sign
layout(std430, binding = 0) readonly buffer FaceData { vec2 face_data[]; };  // (R, law)
flat out vec4 g_plane;          // unit normal (xyz, segment frame) and offset n.q
flat out float g_refl;
flat out int g_law;
out vec3 g_q;
#if LABELS
layout(std430, binding = 2) readonly buffer FaceLabels { uint face_label[]; };
flat out uint g_label;
#endif

void main() {
    float amin = min(v_alpha[0], min(v_alpha[1], v_alpha[2]));
    float amax = max(v_alpha[0], max(v_alpha[1], v_alpha[2]));
    if (amax - amin > alpha_span_max) return;
    vec3 n = frame_sign * cross(v_q[1] - v_q[0], v_q[2] - v_q[0]);
    float len = length(n);
    if (len <= 0.0) return;
    n /= len;
    vec2 face = face_data[gl_PrimitiveIDIn];
    for (int i = 0; i < 3; ++i) {
        gl_Position = gl_in[i].gl_Position;
        g_plane = vec4(n, dot(n, v_q[0]));
        g_refl = face.x;
        g_law = int(face.y + 0.5);
        g_q = v_q[i];
#if LABELS
        g_label = face_label[gl_PrimitiveIDIn];
#endif
        EmitVertex();
    }
    EndPrimitive();
}
#endif

#if defined FRAGMENT_SHADER
flat in vec4 g_plane;
flat in float g_refl;
flat in int g_law;
in vec3 g_q;
uniform sampler2D columns;
#if SCATTERING == 2
uniform sampler2D laws;         // (incidence samples x laws) of f(t) / cos t, R32F
#endif      // per column: (alpha, Phi(alpha - axis) * dalpha, dalpha / 2)
uniform float spacing;          // metres between pings (0 for a stationary sonar)
uniform float rows_per_ping;
uniform float row_width;        // travel of one row, metres
uniform vec3 motion;            // unit direction of travel in (fore, side, up) coordinates
uniform float far_range;
// (centre range, range width from the look-angle extent, range width from the along-track
// extent, weight): the ray bundle of the sample covers an (angle x along-track) patch of the
// plane whose ranges are spread like the sum of two uniform variables of those widths, so
// pass 2 can share the weight among the bins the patch overlaps.
layout(location = 0) out vec4 out_sample;
#if LABELS
flat in uint g_label;
layout(location = 1) out uint out_label;
#endif

float scattering_over_cos(float cos_t) {
#if SCATTERING == 1
    return 1.0;                 // Lambert: cos(theta) * area / cos(theta)
#elif SCATTERING == 2
    // Linear in incidence angle between the two nearest samples (the reference renderer's
    // sediments.law_factor does the same on the CPU).
    int n = textureSize(laws, 0).x;
    float x = acos(clamp(cos_t, 0.0, 1.0)) / 1.5707963267948966 * float(n - 1);
    int j = clamp(int(floor(x)), 0, n - 2);
    float a = texelFetch(laws, ivec2(j, g_law), 0).r;
    float b = texelFetch(laws, ivec2(j + 1, g_law), 0).r;
    return mix(a, b, x - float(j));
#else
#error "unknown SCATTERING"
#endif
}

// Distance along the ray at depression a from `origin` to the plane (or -1).
float hit(vec4 plane, vec3 origin, float a) {
    float denom = dot(plane.xyz, vec3(0.0, cos(a), -sin(a)));
    return denom < -1e-9 ? (plane.w - dot(plane.xyz, origin)) / denom : -1.0;
}

void main() {
    vec3 col = texelFetch(columns, ivec2(int(gl_FragCoord.x), 0), 0).xyz;
    float y = (gl_FragCoord.y / rows_per_ping - 0.5) * spacing;
    vec3 origin = y * motion;
    vec3 dir = vec3(0.0, cos(col.x), -sin(col.x));
    // A face scatters from whichever side the ray meets (an open sheet, a face wound the wrong
    // way); the back of a closed body's face never reaches here, its front is nearer.
    vec4 plane = dot(g_plane.xyz, dir) > 0.0 ? -g_plane : g_plane;
    float cos_t = -dot(plane.xyz, dir);
    float t = hit(plane, origin, col.x);
    if (!(t > 0.0)) t = length(g_q - origin);   // grazing: range of the fragment
    vec4 s = vec4(t, 0.0, 0.0, 0.0);
    if (cos_t > 0.0) {
        float ta = hit(plane, origin, col.x - col.z);
        float tb = hit(plane, origin, col.x + col.z);
        float lo = min(t, min(ta > 0.0 ? ta : t, tb > 0.0 ? tb : t));
        float hi = max(t, max(ta, tb));
        // Range is linear in the travel on a plane: dt/du = -(n . motion) / (n . dir). The fans
        // of consecutive rows lie row_width * motion.x apart (their normal is the fore axis).
        float along = abs(dot(plane.xyz, motion) / cos_t) * row_width;
        float w = g_refl * scattering_over_cos(cos_t) * t * col.y * row_width * motion.x;
        s = vec4(0.5 * (lo + hi), hi - lo, along, w);
    }
    out_sample = s;
#if LABELS
    out_label = g_label;
#endif
    gl_FragDepth = clamp(t / far_range, 0.0, 1.0);
}
#endif
