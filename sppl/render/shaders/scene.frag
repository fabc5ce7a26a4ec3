#version 330

uniform vec3 colour;
uniform bool ray_depth;  // distance from the optical centre instead of along the optical axis
uniform float depth_max;

in vec3 v_normal;
in vec3 v_camera;
#ifdef RAY_CAST
uniform mat3 normal_matrix;
uniform mat4 projection;
flat in vec3 v_origin;
flat in mat3 v_unit_from_camera;
#endif

layout(location = 0) out vec4 out_colour;
layout(location = 1) out float out_depth;

void main() {
    vec3 normal = v_normal;
    vec3 camera_point = v_camera;
#ifdef RAY_CAST
    vec3 ray = pixel_ray();
    float t;
    vec3 unit_normal;
    if (!HIT(v_origin, v_unit_from_camera, ray, t, unit_normal)) discard;
    camera_point = t * ray;
    normal = normal_matrix * unit_normal;
    gl_FragDepth = window_depth(projection, camera_point);
#endif
    out_colour = vec4(shade(colour, normal, camera_point), 1.0);
    float depth = ray_depth ? length(camera_point) : -camera_point.z;
    out_depth = min(depth, depth_max);
}
