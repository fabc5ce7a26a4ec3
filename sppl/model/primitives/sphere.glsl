// The unit sphere: radius 1, centre (0, 0, 1).
bool sphere_hit(vec3 camera, mat3 unit_from_camera, vec3 ray, out float t, out vec3 normal) {
    vec3 origin = camera - vec3(0.0, 0.0, 1.0);  // relative to the centre
    vec3 d = unit_from_camera * ray;
    float a = dot(d, d);
    // Through the point of the ray closest to the centre, which keeps the discriminant accurate
    // in single precision far from the sphere.
    float middle = -dot(origin, d) / a;
    vec3 closest = origin + middle * d;
    float discriminant = 1.0 - dot(closest, closest);
    if (discriminant < 0.0) return false;
    float half_chord = sqrt(discriminant / a);
    t = middle - half_chord;
    if (t <= near) t = middle + half_chord;
    if (t <= near) return false;
    normal = origin + t * d;
    return true;
}
