#version 330

// Flat-shaded unit mesh posed by the part's world-from-unit matrix (scale included). Compiled
// with RAY_CAST defined, it draws a round shape's proxy and passes what ray_cast.glsl needs.
uniform mat4 model;
uniform mat3 normal_matrix;  // inverse-transpose of model's 3x3: right under non-uniform scale
uniform mat4 view;           // world to camera (OpenGL axes)
uniform mat4 projection;

in vec3 in_position;
in vec3 in_normal;

out vec3 v_normal;  // world space
out vec3 v_camera;  // camera-space position, for exact metric depth
#ifdef RAY_CAST
flat out vec3 v_origin;           // the camera's origin in unit coordinates
flat out mat3 v_unit_from_camera;
#endif

void main() {
    vec4 camera_point = view * (model * vec4(in_position, 1.0));
    v_normal = normal_matrix * in_normal;
    v_camera = camera_point.xyz;
    gl_Position = projection * camera_point;
#ifdef RAY_CAST
    mat3 unit_from_world = transpose(normal_matrix);
    mat3 world_from_camera = transpose(mat3(view));
    vec3 eye = -(world_from_camera * view[3].xyz);
    v_origin = unit_from_world * (eye - model[3].xyz);
    v_unit_from_camera = unit_from_world * world_from_camera;
#endif
}
