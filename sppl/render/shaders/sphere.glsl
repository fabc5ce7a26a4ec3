// Spheres are drawn exactly: a part's unit sphere (radius 1, centred at (0, 0, 1)) under its
// affine map is an ellipsoid, and each pixel's ray is intersected with it here instead of
// rasterising a tessellation. The vertex shader draws an inside-out bounding box (its far
// faces) to reach every pixel the ellipsoid may cover and passes, per part, the camera's
// origin and the camera-to-unit linear map in the unit sphere's coordinates.
uniform vec4 intrinsics;  // fx, fy, cx, cy in pixels
uniform float near;

// The ray through this fragment's pixel centre, (u, v) = gl_FragCoord.xy (the projection's y
// flip makes window rows image rows), in camera coordinates scaled so that its z is -1: the
// ray's parameter is then the z-depth of its points.
vec3 pixel_ray() {
    return vec3((gl_FragCoord.x - intrinsics.z) / intrinsics.x,
                -(gl_FragCoord.y - intrinsics.w) / intrinsics.y, -1.0);
}

// The nearest intersection beyond the near plane, as the ray's parameter (its z-depth) and the
// hit point relative to the sphere's centre in unit coordinates (the unit-space normal);
// false when the ray misses. A camera inside the sphere, or one whose near plane cuts it,
// sees the far side, as it sees a mesh's back faces.
bool sphere_hit(vec3 origin, mat3 unit_from_camera, vec3 ray, out float t, out vec3 normal) {
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

// gl_FragDepth of a camera-space point, as the rasteriser would interpolate it.
float window_depth(mat4 projection, vec3 camera_point) {
    vec4 clip = projection * vec4(camera_point, 1.0);
    return 0.5 * (clip.z / clip.w) + 0.5;
}
