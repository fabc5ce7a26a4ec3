#version 330

// Flat-shaded unit mesh posed by the part's world-from-unit matrix (scale included).
uniform mat4 model;
uniform mat3 normal_matrix;  // inverse-transpose of model's 3x3: right under non-uniform scale
uniform mat4 view;           // world to camera (OpenGL axes)
uniform mat4 projection;

in vec3 in_position;
in vec3 in_normal;

out vec3 v_normal;  // world space
out vec3 v_camera;  // camera-space position, for exact metric depth

void main() {
    vec4 camera_point = view * (model * vec4(in_position, 1.0));
    v_normal = normal_matrix * in_normal;
    v_camera = camera_point.xyz;
    gl_Position = projection * camera_point;
}
