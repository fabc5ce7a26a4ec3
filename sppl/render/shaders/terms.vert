#version 330

// scene.vert with each part's matrices and colour as per-instance attributes, so that all the
// parts of one primitive are one draw call. The arithmetic is scene.vert's, in the same order,
// so that both rasterise the same pixels (and, with RAY_CAST defined, hit the same shapes).
uniform mat4 view;
uniform mat4 projection;

in vec3 in_position;
in vec3 in_normal;
in mat4 i_model;
in mat3 i_normal;  // inverse-transpose of i_model's 3x3
in vec3 i_colour;

out vec3 v_normal;
out vec3 v_camera;
flat out vec3 v_colour;
#ifdef RAY_CAST
flat out vec3 v_origin;
flat out mat3 v_unit_from_camera;
flat out mat3 v_normal_matrix;
#endif

void main() {
    vec4 camera_point = view * (i_model * vec4(in_position, 1.0));
    v_normal = i_normal * in_normal;
    v_camera = camera_point.xyz;
    v_colour = i_colour;
    gl_Position = projection * camera_point;
#ifdef RAY_CAST
    mat3 unit_from_world = transpose(i_normal);
    mat3 world_from_camera = transpose(mat3(view));
    vec3 eye = -(world_from_camera * view[3].xyz);
    v_origin = unit_from_world * (eye - i_model[3].xyz);
    v_unit_from_camera = unit_from_world * world_from_camera;
    v_normal_matrix = i_normal;
#endif
}
