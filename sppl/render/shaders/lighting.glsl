// Lighting and cast shadows, shared by scene.frag and terms.frag (renderer.py prepends it).
// The settings are a uniform block (lighting.py packs it) rather than plain uniforms: a model
// may leave the lighting uncertain, so they change between hypotheses, and one buffer bound to
// every program is rewritten once per hypothesis instead of each program's uniforms.
//
// A shadow is exact, not a shadow map: from the surface point a pixel shows, a ray goes
// towards the light and is tested against every part's solid (a box, or the affine image of
// the unit sphere, cylinder or cone). The point is in shadow when the ray is inside a solid
// somewhere beyond SHADOW_BIAS metres. Parts are convex, so a point lit by the light leaves
// its own part at once and its own part never shadows it: the bias only has to absorb
// rounding. raycast.py computes the same in double precision, from the triangles of a box.
#define MAX_CASTERS 252
#define SHADOW_BIAS 1.0e-3
#define CASTER_BOX 0
#define CASTER_SPHERE 1
#define CASTER_CYLINDER 2
#define CASTER_CONE 3

layout(std140) uniform Lighting {
    vec4 light_direction;  // xyz: the unit vector towards the light, world space
    vec4 shading;          // ambient, intensity, the number of casters, shadows on (1) or off (0)
    vec4 balance;          // rgb per channel: the gain times the white balance; w: the sheen
    // Per caster, four rows: its unit-from-world affine map (rows of [linear | offset]), and
    // (kind, 0, 0, 0).
    vec4 casters[4 * MAX_CASTERS];
};

uniform mat4 view;

// Narrows [lo, hi] to the ray's parameters with a <= o + s v <= b.
void slab(float o, float v, float a, float b, inout float lo, inout float hi) {
    if (v == 0.0) {
        if (o < a || o > b) { lo = 3.0e38; hi = -3.0e38; }
        return;
    }
    float s0 = (a - o) / v;
    float s1 = (b - o) / v;
    lo = max(lo, min(s0, s1));
    hi = min(hi, max(s0, s1));
}

// Whether the piece [lo, hi] of the ray is inside the solid beyond the bias.
bool reaches(float lo, float hi) {
    return lo <= hi && hi > SHADOW_BIAS;
}

// Whether the ray o + s v (unit coordinates; s is metres along the world ray) is inside a
// round solid beyond the bias: sphere, or the slab 0 <= z <= 1 of x^2 + y^2 = (1 - slope z)^2.
bool round_blocks(int kind, vec3 o, vec3 v) {
    if (kind == CASTER_SPHERE) {
        vec3 c = o - vec3(0.0, 0.0, 1.0);
        float a = dot(v, v);
        float b = dot(c, v);
        float d = b * b - a * (dot(c, c) - 1.0);
        if (d < 0.0) return false;
        float r = sqrt(d);
        return reaches((-b - r) / a, (-b + r) / a);
    }
    float lo = -3.0e38;
    float hi = 3.0e38;
    slab(o.z, v.z, 0.0, 1.0, lo, hi);
    if (lo > hi) return false;
    float slope = kind == CASTER_CONE ? 1.0 : 0.0;
    float w = 1.0 - slope * o.z;
    float e = slope * v.z;
    // (o + s v) inside: a s^2 + 2 b s + c <= 0.
    float a = dot(v.xy, v.xy) - e * e;
    float b = dot(o.xy, v.xy) + w * e;
    float c = dot(o.xy, o.xy) - w * w;
    if (a == 0.0) {
        if (b == 0.0) return c <= 0.0 && reaches(lo, hi);
        float s = -c / (2.0 * b);
        return b > 0.0 ? reaches(lo, min(hi, s)) : reaches(max(lo, s), hi);
    }
    float d = b * b - a * c;
    if (d < 0.0) return a < 0.0 && reaches(lo, hi);  // a < 0: inside along the whole line
    float r = sqrt(d);
    float s0 = min((-b - r) / a, (-b + r) / a);
    float s1 = max((-b - r) / a, (-b + r) / a);
    if (a > 0.0) return reaches(max(lo, s0), min(hi, s1));
    // a < 0 (a cone seen along its side): inside before s0 and after s1; the slab keeps the
    // lower nappe's piece.
    return reaches(lo, min(hi, s0)) || reaches(max(lo, s1), hi);
}

bool caster_blocks(int i, vec3 p, vec3 d) {
    vec4 r0 = casters[4 * i];
    vec4 r1 = casters[4 * i + 1];
    vec4 r2 = casters[4 * i + 2];
    int kind = int(casters[4 * i + 3].x);
    vec3 o = vec3(dot(r0.xyz, p) + r0.w, dot(r1.xyz, p) + r1.w, dot(r2.xyz, p) + r2.w);
    vec3 v = vec3(dot(r0.xyz, d), dot(r1.xyz, d), dot(r2.xyz, d));
    if (kind == CASTER_BOX) {
        float lo = -3.0e38;
        float hi = 3.0e38;
        slab(o.x, v.x, -0.5, 0.5, lo, hi);
        slab(o.y, v.y, -0.5, 0.5, lo, hi);
        slab(o.z, v.z, 0.0, 1.0, lo, hi);
        return reaches(lo, hi);
    }
    return round_blocks(kind, o, v);
}

// 1 where the camera-space point sees the light past every caster, else 0.
float lit(vec3 camera_point) {
    mat3 world_from_camera = transpose(mat3(view));
    vec3 p = world_from_camera * (camera_point - view[3].xyz);
    vec3 d = light_direction.xyz;
    int n = int(shading.z);
    for (int i = 0; i < n; i++) {
        if (caster_blocks(i, p, d)) return 0.0;
    }
    return 1.0;
}

// A part's colour as lit at a point with this normal (not yet normalised). The sheen is grey
// added whatever the colour and the light: the sky a rough surface mirrors.
vec3 shade(vec3 colour, vec3 normal, vec3 camera_point) {
    float lambert = max(dot(normalize(normal), light_direction.xyz), 0.0);
    if (lambert > 0.0 && shading.w > 0.5) lambert *= lit(camera_point);
    float ambient = shading.x;
    return balance.rgb * (colour * (ambient + shading.y * (1.0 - ambient) * lambert) + balance.w);
}
