#version 330

uniform vec3 colour;
uniform vec3 light;      // unit direction towards the light, world space
uniform float ambient;
uniform bool ray_depth;  // distance from the optical centre instead of along the optical axis
uniform float depth_max;

in vec3 v_normal;
in vec3 v_camera;

layout(location = 0) out vec4 out_colour;
layout(location = 1) out float out_depth;

void main() {
    float lambert = max(dot(normalize(v_normal), light), 0.0);
    out_colour = vec4(colour * (ambient + (1.0 - ambient) * lambert), 1.0);
    float depth = ray_depth ? length(v_camera) : -v_camera.z;
    out_depth = min(depth, depth_max);
}
