// Ray-cast primitives are drawn exactly: each pixel's ray is intersected with the part's unit
// shape (an ellipsoid, or an elliptic cylinder or cone, once the part's affine map acts on
// it) instead of rasterising a tessellation. The vertex shader draws an inside-out convex
// proxy around the shape (its far faces) to reach every pixel the shape may cover and passes,
// per part, the camera's origin and the camera-to-unit linear map in the unit shape's
// coordinates. Each ray-cast primitive's own snippet (sppl/model/primitives/NAME.glsl) follows
// this file and defines NAME_hit; the program is compiled with HIT defined as that function.
uniform vec4 intrinsics;  // fx, fy, cx, cy in pixels
uniform float near;

// The ray through this fragment's pixel centre, (u, v) = gl_FragCoord.xy (the projection's y
// flip makes window rows image rows), in camera coordinates scaled so that its z is -1: the
// ray's parameter is then the z-depth of its points.
vec3 pixel_ray() {
    return vec3((gl_FragCoord.x - intrinsics.z) / intrinsics.x,
                -(gl_FragCoord.y - intrinsics.w) / intrinsics.y, -1.0);
}

// Each NAME_hit(origin, unit_from_camera, ray, out t, out normal) gives the nearest
// intersection beyond the near plane of the ray origin + t * unit_from_camera * ray (origin:
// the camera in the unit shape's coordinates; ray: pixel_ray()), as the ray's parameter t
// (its z-depth) and the unit shape's outward normal there (any length); false when the ray
// misses. A camera inside the shape, or one whose near plane cuts it, sees the far side, as it
// sees a mesh's back faces. The helpers below serve quadric shapes.

// Keeps a candidate hit at s along the ray from its point p0 (t = middle + s) if it lies beyond
// the near plane and before the best so far.
void keep(float middle, float s, vec3 n, inout float best, inout vec3 normal) {
    float t = middle + s;
    if (t > near && t < best) {
        best = t;
        normal = n;
    }
}

// The roots of a s^2 + 2 b s + c = 0 in the stable form; false when there are none.
bool roots(float a, float b, float c, out float s0, out float s1) {
    float discriminant = b * b - a * c;
    if (discriminant < 0.0) return false;
    float q = -(b + (b < 0.0 ? -1.0 : 1.0) * sqrt(discriminant));
    if (q == 0.0) return false;  // a = b = c = 0 on a degenerate ray, or a tangent at s = 0
    s0 = c / q;
    s1 = a != 0.0 ? q / a : s0;  // a = 0: a ray along the cone's side meets it once
    return true;
}

// Keeps the ray's hit with the disc of radius 1 in the plane z = height.
void cap(float middle, vec3 p0, vec3 d, float height, inout float best, inout vec3 normal) {
    if (d.z == 0.0) return;
    float s = (height - p0.z) / d.z;
    vec2 p = p0.xy + s * d.xy;
    if (dot(p, p) <= 1.0) keep(middle, s, vec3(0.0, 0.0, height > 0.5 ? 1.0 : -1.0), best, normal);
}

// The unit cylinder (slope 0: radius 1 about the z axis, z in [0, 1], with both caps) or cone
// (slope 1: base radius 1 at z = 0, apex at z = 1, with its base): x^2 + y^2 = (1 - slope z)^2
// for z in [0, 1], which also keeps the cone's upper nappe out.
bool round_hit(vec3 origin, mat3 unit_from_camera, vec3 ray, float slope, out float t,
               out vec3 normal) {
    vec3 d = unit_from_camera * ray;
    // Solved from the ray's point nearest the middle of the unit box, where every coefficient
    // is of the shape's size: accurate in single precision however far away the camera is.
    float middle = -dot(origin - vec3(0.0, 0.0, 0.5), d) / dot(d, d);
    vec3 p0 = origin + middle * d;
    float best = 3.0e38;
    float s[2];
    float w = 1.0 - slope * p0.z;
    float e = slope * d.z;
    if (roots(dot(d.xy, d.xy) - e * e, dot(p0.xy, d.xy) + w * e, dot(p0.xy, p0.xy) - w * w,
              s[0], s[1])) {
        for (int i = 0; i < 2; i++) {
            vec3 p = p0 + s[i] * d;
            if (p.z >= 0.0 && p.z <= 1.0)
                keep(middle, s[i], vec3(p.xy, slope * (1.0 - p.z)), best, normal);
        }
    }
    cap(middle, p0, d, 0.0, best, normal);
    if (slope == 0.0) cap(middle, p0, d, 1.0, best, normal);
    t = best;
    if (best == 3.0e38) return false;
    // The cone's apex has no normal: light it as the tip of the axis.
    if (normal == vec3(0.0)) normal = vec3(0.0, 0.0, 1.0);
    return true;
}

// gl_FragDepth of a camera-space point, as the rasteriser would interpolate it.
float window_depth(mat4 projection, vec3 camera_point) {
    vec4 clip = projection * vec4(camera_point, 1.0);
    return 0.5 * (clip.z / clip.w) + 0.5;
}
