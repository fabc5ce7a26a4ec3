#version 330

// Shades a fragment as scene.frag does, then writes its pixel's likelihood term instead of its
// colour: for each modality, (observed - rendered)^2 minus (observed - background)^2, or for a
// robust likelihood (likelihood.glsl, put above this by pixels.py) its log density at the
// rendering less at the background. The background is seen through the camera's gain and white
// balance (lighting.glsl's block), as scene.frag renders it. Pixels no part covers keep the
// cleared 0, so the image's sum is the statistic less that of the empty scene, which is
// computed on the CPU.
uniform bool ray_depth;
uniform float depth_max;
uniform vec3 background;
uniform sampler2D observed;  // rgb, depth in alpha; MISSING (pixels.py) marks no term there
// Observations may be negative (simulated noise): only pixels.py's MISSING, -3e38, marks a
// missing value.
const float MISSING_BELOW = -1.0e37;

in vec3 v_normal;
in vec3 v_camera;
flat in vec3 v_colour;
#ifdef RAY_CAST
uniform mat4 projection;
flat in vec3 v_origin;
flat in mat3 v_unit_from_camera;
flat in mat3 v_normal_matrix;
#endif

layout(location = 0) out vec2 out_terms;  // (image term, depth term)

void main() {
    vec3 normal = v_normal;
    vec3 camera_point = v_camera;
#ifdef RAY_CAST
    vec3 ray = pixel_ray();
    float t;
    vec3 unit_normal;
    if (!HIT(v_origin, v_unit_from_camera, ray, t, unit_normal)) discard;
    camera_point = t * ray;
    normal = v_normal_matrix * unit_normal;
    gl_FragDepth = window_depth(projection, camera_point);
#endif
    vec3 colour = shade(v_colour, normal, camera_point);
    float depth = ray_depth ? length(camera_point) : -camera_point.z;
    depth = min(depth, depth_max);
    vec4 o = texelFetch(observed, ivec2(gl_FragCoord.xy), 0);
    float image = 0.0;
    if (o.r > MISSING_BELOW) {
#if IMAGE_TERM != 0
        image = image_density(o.rgb, colour) - image_density(o.rgb, balance.rgb * background);
#else
        vec3 a = o.rgb - colour;
        vec3 b = o.rgb - balance.rgb * background;
        image = dot(a, a) - dot(b, b);
#endif
    }
    float range = 0.0;
#if DEPTH_TERM != 0
    // A robust likelihood's term: the pixel's log density less the empty scene's.
    bool present = o.a > MISSING_BELOW;
    range = depth_density(o.a, present, depth, depth_max)
          - depth_density(o.a, present, depth_max, depth_max);
#else
    if (o.a > MISSING_BELOW) {
        float a = o.a - depth;
        float b = o.a - depth_max;
        range = a * a - b * b;
    }
#endif
    out_terms = vec2(image, range);
}
