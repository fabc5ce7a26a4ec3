// The robust likelihoods' per-pixel log densities (sppl/robust.py is their numpy twin, and its
// docstring their definition). pixels.py puts this file at the top of terms.frag, after
// defines that pick each modality's likelihood: IMAGE_TERM and DEPTH_TERM, 0 for the Gaussian
// (terms.frag's own squared residuals), 1 the mixture with a Gaussian inlier, 2 with a Laplace
// inlier, 3 Student-t; DEPTH_RETURNS 1 scores missing depth pixels.
//
// Each modality's noise, as robust.py's ``uniforms`` gives it:
//   mixture, Gaussian inlier: (1 / (2 sigma^2), log(1 - w) - k/2 log(2 pi) - k log sigma,
//                              log w - k log(range), 0)
//   mixture, Laplace inlier:  (1 / sigma, log(1 - w) - k log(2 sigma), log w - k log(range), 0)
//   Student-t:                (1 / (nu sigma^2), -(nu + k) / 2, its log normaliser, 0)
uniform vec4 image_noise;
uniform vec4 depth_noise;
// log missing, log(1 - missing), log missing_far, log(1 - missing_far)
uniform vec4 depth_returns;

float log1p_(float x) {
    // float32's log(1 + x) loses x below 1e-7; the series keeps it for small x.
    return x < 1.0e-3 ? x * (1.0 - x * (0.5 - x / 3.0)) : log(1.0 + x);
}

// A pixel's log density given its distance from the rendering (the squared norm of the
// residual, or its absolute sum for a Laplace inlier) and whether the observation lies in the
// sensor's range.
float value_density(int term, vec4 p, float dist, bool in_range) {
    if (term == 3) return p.z + p.y * log1p_(p.x * dist);
    float a = p.y - p.x * dist;
    if (!in_range) return a;
    float m = max(a, p.z);
    return m + log1p_(exp(min(a, p.z) - m));
}

#if IMAGE_TERM != 0
float image_density(vec3 o, vec3 r) {
    vec3 d = o - r;
#if IMAGE_TERM == 2
    float dist = abs(d.r) + abs(d.g) + abs(d.b);
#else
    float dist = dot(d, d);
#endif
    bool in_range = all(greaterThanEqual(o, vec3(0.0))) && all(lessThanEqual(o, vec3(1.0)));
    return value_density(IMAGE_TERM, image_noise, dist, in_range);
}
#endif

#if DEPTH_TERM != 0
// o: the observed depth (present says whether it is), r: the rendered depth, clipped at
// depth_max, which means no surface in range.
float depth_density(float o, bool present, float r, float depth_max) {
    bool surface = r < depth_max;
#if DEPTH_RETURNS
    if (!present) return surface ? depth_returns.x : depth_returns.z;
    float given = surface ? depth_returns.y : depth_returns.w;
#else
    if (!present) return 0.0;
    float given = 0.0;
#endif
    float d = o - r;
#if DEPTH_TERM == 2
    float dist = abs(d);
#else
    float dist = d * d;
#endif
    return given + value_density(DEPTH_TERM, depth_noise, dist, o >= 0.0 && o <= depth_max);
}
#endif
