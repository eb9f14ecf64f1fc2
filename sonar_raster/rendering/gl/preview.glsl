#version 330 core
// Preview of the recovered seabed mesh: grey texture times a Lambert term of one directional
// light plus ambient. No defines needed.

#if defined VERTEX_SHADER
in vec3 in_pos;       // metres, centred, vertical exaggeration applied
in vec3 in_normal;
in float in_grey;     // 0..1
uniform mat4 mvp;
out vec3 v_normal;
out float v_grey;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    v_normal = in_normal;
    v_grey = in_grey;
}
#endif

#if defined FRAGMENT_SHADER
in vec3 v_normal;
in float v_grey;
uniform vec3 light_dir;  // unit vector towards the light
out vec4 f_color;
void main() {
    float lambert = abs(dot(normalize(v_normal), light_dir));
    float shade = v_grey * (0.35 + 0.65 * lambert);
    f_color = vec4(vec3(shade), 1.0);
}
#endif
