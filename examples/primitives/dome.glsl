// The unit dome: the upper half of the sphere of radius 1 about the origin (z in [0, 1]),
// closed by its base, the disc of radius 1 at z = 0. keep, roots and cap are ray_cast.glsl's.
bool dome_hit(vec3 origin, mat3 unit_from_camera, vec3 ray, out float t, out vec3 normal) {
    vec3 d = unit_from_camera * ray;
    // Solved from the ray's point nearest the centre, where every coefficient is of the
    // shape's size: accurate in single precision however far away the camera is.
    float middle = -dot(origin, d) / dot(d, d);
    vec3 p0 = origin + middle * d;
    float best = 3.0e38;
    float s[2];
    if (roots(dot(d, d), dot(p0, d), dot(p0, p0) - 1.0, s[0], s[1])) {
        for (int i = 0; i < 2; i++) {
            vec3 p = p0 + s[i] * d;
            if (p.z >= 0.0) keep(middle, s[i], p, best, normal);  // on the sphere, its normal is p
        }
    }
    cap(middle, p0, d, 0.0, best, normal);
    t = best;
    return best < 3.0e38;
}
