// The unit cone: ray_cast.glsl's round_hit with slope 1.
bool cone_hit(vec3 origin, mat3 unit_from_camera, vec3 ray, out float t, out vec3 normal) {
    return round_hit(origin, unit_from_camera, ray, 1.0, t, normal);
}
