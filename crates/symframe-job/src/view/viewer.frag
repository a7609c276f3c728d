#version 300 es
// symframe viewer: relights fitted Ward or glTF maps (or an estimate's frames with a fixed
// material), or shows one map, for one tile of the maps at a time; each canvas pixel shows the
// texel under its centre (nearest neighbour).
//
// The relit view is `symframe relight`'s image (symframe::Relighter): the radiance
// f(l, v) (n.l) of each pixel's model in its frame (x = t, y = b = n x t, z = n), view
// v = (0, 0, 1), a distant light of unit intensity (a glTF fit: of its fitted intensity). The
// model is anisotropic Ward (normalised form, Ward 1992) or glTF 2.0 metallic-roughness with
// KHR_materials_anisotropy (symframe::brdf::gltf); the same edits (Ward: factors on kd, ks and
// both roughnesses; glTF: on the base colour and the roughness, clamped to 1; tangents turned
// about the normal); then the PNG's tone mapping: times 2^exposure, clamped to [0, 1],
// sRGB-encoded.
precision highp float;
precision highp int;

uniform highp sampler2D uGeom;   // normal, flag (0 none, 1 normal only, 2 model, 3 glTF in
                                 // an automatic fit of both models)
uniform highp sampler2D uFrame;  // shading tangent, 1 if from the tangent map
uniform highp sampler2D uKd;     // Ward: kd, alpha_t; glTF: base colour, metallic
uniform highp sampler2D uKs;     // Ward: ks, alpha_b; glTF: roughness, strength, 0, 0
uniform highp sampler2D uEst;    // confidence, anisotropy, source, flags (1, 2, 4)
uniform int uView;               // 0 relit, 1 normal, 2 tangent, 3 kd, 4 ks, 5 confidence,
                                 // 6 anisotropy, 7 source, 8 base colour, 9 samples
// The view `samples` (view/samples.rs): layer 0 normal and 1 with a frame, layer 1 tangent,
// layer 2 + k the RGB slice (radiance over n.l) under light k and 1 where valid; the rig's
// triangles, three texels a row: a row of the spherical inverse and that corner's light.
uniform highp sampler2DArray uSamples;
uniform highp sampler2D uTris;
uniform int uTriangles;
uniform int uModel;              // 0 Ward (glTF where flag 3), 1 glTF, 2 an estimate
uniform float uIntensity;        // glTF: the fitted light intensity
uniform vec3 uLight;             // unit light direction, camera frame
uniform float uGain;             // 2^exposure
uniform float uDiffuse;          // factor on kd
uniform float uSpecular;         // factor on ks
uniform float uRoughness;        // factor on alpha_t and alpha_b
uniform vec2 uRotation;          // (cos, sin) of the tangent rotation
// Where the tile is: the canvas pixel (device pixels, y down) shows map point
// uCenter + (pixel - uCanvas / 2) / uZoom; the tile's texel (i, j) covers the map pixels from
// uOrigin + (i, j) * uScale, uScale on a side (a coarse level).
uniform vec2 uCenter;
uniform float uZoom;
uniform vec2 uCanvas;
uniform vec2 uOrigin;
uniform float uScale;

out vec4 outColor;

const float PI = 3.14159265358979;

// symframe_io's linear_to_srgb.
float srgb(float v) {
    return v <= 0.0031308 ? v * 12.92 : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
}

vec3 srgb3(vec3 v) {
    v = clamp(v, 0.0, 1.0);
    return vec3(srgb(v.r), srgb(v.g), srgb(v.b));
}

// symframe_io's viridis polynomial (within about 1% of matplotlib's map).
vec3 viridis(float t) {
    t = clamp(t, 0.0, 1.0);
    const vec3 c0 = vec3(0.2777273272234177, 0.005407344544966578, 0.3340998053353061);
    const vec3 c1 = vec3(0.1050930431085774, 1.404613529898575, 1.384590162594685);
    const vec3 c2 = vec3(-0.3308618287255563, 0.214847559468213, 0.09509516302823659);
    const vec3 c3 = vec3(-4.634230498983486, -5.799100973351585, -19.33244095627987);
    const vec3 c4 = vec3(6.228269936347081, 14.17993336680509, 56.69055260068105);
    const vec3 c5 = vec3(4.776384997670288, -13.74514537774601, -65.35303263337234);
    const vec3 c6 = vec3(-5.435455855934631, 4.645852612178535, 26.3124352495832);
    return clamp(c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6))))), 0.0, 1.0);
}

// symframe_io's tangent picture: hue 2 phi (t and -t alike), saturation and value 1.
vec3 hue(float turns) {
    float h = fract(turns) * 6.0;
    float s = min(floor(h), 5.0);
    float f = h - s;
    if (s == 0.0) return vec3(1.0, f, 0.0);
    if (s == 1.0) return vec3(1.0 - f, 1.0, 0.0);
    if (s == 2.0) return vec3(0.0, 1.0, f);
    if (s == 3.0) return vec3(0.0, 1.0 - f, 1.0);
    if (s == 4.0) return vec3(f, 0.0, 1.0);
    return vec3(1.0, 0.0, 1.0 - f);
}

// The tangent after the edit: turned about n where it came from the tangent map.
vec3 editedTangent(vec3 t, vec3 n, float fromMap) {
    if (fromMap > 0.5) {
        t = t * uRotation.x + cross(n, t) * uRotation.y;
    }
    return t;
}

// Ward radiance f(l, v) (n.l) in the frame (t, n x t, n); 0 when l or v is at or below the
// horizon (symframe::brdf::ward, half_vector_above).
vec3 ward(vec3 n, vec3 t, vec3 kd, vec3 ks, float ax, float ay, vec3 l) {
    vec3 b = cross(n, t);
    vec3 ll = vec3(dot(l, t), dot(l, b), dot(l, n));
    vec3 vl = vec3(t.z, b.z, n.z);
    if (ll.z <= 0.0 || vl.z <= 0.0) {
        return vec3(0.0);
    }
    vec3 h = normalize(ll + vl);
    float sx = h.x / ax;
    float sy = h.y / ay;
    float e = (sx * sx + sy * sy) / (h.z * h.z);
    float lobe = exp(-e) / (4.0 * PI * ax * ay * sqrt(ll.z * vl.z));
    return (kd / PI + ks * lobe) * ll.z;
}

// glTF radiance intensity f(l, v) (n.l), f = base A + B (symframe::brdf::gltf::GltfPbr::terms):
// GGX D and height-correlated V of KHR_materials_anisotropy, alpha_t = mix(alpha, 1, s^2),
// alpha_b = alpha = roughness^2, Schlick on v.h; dielectric fresnel_mix (f0 0.04) and conductor
// mixed by metallic.
vec3 gltf(vec3 n, vec3 t, vec3 base, float metallic, float roughness, float strength, vec3 l) {
    vec3 b = cross(n, t);
    vec3 ll = vec3(dot(l, t), dot(l, b), dot(l, n));
    vec3 vl = vec3(t.z, b.z, n.z);
    if (ll.z <= 0.0 || vl.z <= 0.0) {
        return vec3(0.0);
    }
    vec3 h = normalize(ll + vl);
    float a = roughness * roughness;
    float at = a + (1.0 - a) * strength * strength;
    float ab = a;
    vec3 f = vec3(ab * h.x, at * h.y, at * ab * h.z);
    float w2 = at * ab / dot(f, f);
    float d = at * ab * w2 * w2 / PI;
    float gv = ll.z * length(vec3(at * vl.x, ab * vl.y, vl.z));
    float gl = vl.z * length(vec3(at * ll.x, ab * ll.y, ll.z));
    float spec = min(0.5 / (gv + gl), 1.0) * d;
    float s = pow(1.0 - abs(dot(vl, h)), 5.0);
    float fd = 0.04 + 0.96 * s;
    float ta = (1.0 - metallic) * (1.0 - fd) / PI + metallic * (1.0 - s) * spec;
    float tb = ((1.0 - metallic) * fd + metallic * s) * spec;
    return (base * ta + tb) * ll.z;
}

// An estimate's stand-in material: grey Lambert plus a Ward lobe, stretched along the
// tangent where the estimate has one (alpha 0.35 along, 0.12 across; 0.2 where isotropic),
// times the edits' factors.
vec3 estimateShade(vec3 n, vec4 frame, vec3 l) {
    n = normalize(n);
    vec3 t;
    float ax = 0.2, ay = 0.2;
    if (frame.w > 0.5) {
        t = normalize(frame.xyz - dot(frame.xyz, n) * n);
        t = editedTangent(t, n, frame.w);
        ax = 0.35;
        ay = 0.12;
    } else {
        vec3 a = abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
        t = normalize(a - dot(a, n) * n);
    }
    return ward(n, t, vec3(0.5 * uDiffuse), vec3(0.15 * uSpecular), ax * uRoughness,
                ay * uRoughness, l);
}

// The slice of pixel p at unit halfway vector h, as symframe::SampleRelighter reads it: the
// first triangle holding h (no spherical barycentric weight below zero), its weights over the
// corners with data renormalised; false outside the triangles or where no corner has data.
bool sliceAt(ivec2 p, vec3 h, out vec3 value) {
    for (int k = 0; k < uTriangles; k++) {
        vec4 r0 = texelFetch(uTris, ivec2(0, k), 0);
        vec4 r1 = texelFetch(uTris, ivec2(1, k), 0);
        vec4 r2 = texelFetch(uTris, ivec2(2, k), 0);
        vec3 w = vec3(dot(r0.xyz, h), dot(r1.xyz, h), dot(r2.xyz, h));
        if (min(w.x, min(w.y, w.z)) < -1e-6) {
            continue;
        }
        w /= w.x + w.y + w.z;
        vec4 s0 = texelFetch(uSamples, ivec3(p, int(r0.w + 0.5) + 2), 0);
        vec4 s1 = texelFetch(uSamples, ivec3(p, int(r1.w + 0.5) + 2), 0);
        vec4 s2 = texelFetch(uSamples, ivec3(p, int(r2.w + 0.5) + 2), 0);
        vec3 ws = vec3(w.x > 0.0 && s0.w > 0.5 ? w.x : 0.0, w.y > 0.0 && s1.w > 0.5 ? w.y : 0.0,
                       w.z > 0.0 && s2.w > 0.5 ? w.z : 0.0);
        float sum = ws.x + ws.y + ws.z;
        if (sum <= 0.0) {
            return false;
        }
        value = (ws.x * s0.rgb + ws.y * s1.rgb + ws.z * s2.rgb) / sum;
        return true;
    }
    return false;
}

// The capture relit from its own samples (symframe::SampleRelighter::render): the slice at
// the light's halfway vector, or at its mirror images in the pixel's frame, times n.l.
vec3 samplesShade(ivec2 p, vec3 l) {
    vec4 f0 = texelFetch(uSamples, ivec3(p, 0), 0);
    if (f0.w < 0.5) {
        return vec3(0.0);
    }
    vec3 n = normalize(f0.xyz);
    vec3 t = texelFetch(uSamples, ivec3(p, 1), 0).xyz;
    t = normalize(t - dot(t, n) * n);
    float nl = dot(n, l);
    vec3 hv = l + vec3(0.0, 0.0, 1.0);
    if (nl <= 0.0 || dot(hv, hv) < 1e-12) {
        return vec3(0.0);
    }
    vec3 h = normalize(hv);
    vec3 b = cross(n, t);
    vec3 ht = dot(h, t) * t;
    vec3 hb = dot(h, b) * b;
    vec3 v;
    if (sliceAt(p, h, v) || sliceAt(p, h - 2.0 * hb, v) || sliceAt(p, h - 2.0 * ht, v)
        || sliceAt(p, h - 2.0 * (ht + hb), v)) {
        return max(v, 0.0) * nl;
    }
    return vec3(0.0);
}

void main() {
    ivec2 size = textureSize(uGeom, 0);
    // The canvas' y runs bottom to top, the map's and the textures' rows top to bottom.
    vec2 screen = vec2(gl_FragCoord.x, uCanvas.y - gl_FragCoord.y);
    vec2 m = uCenter + (screen - 0.5 * uCanvas) / uZoom;
    ivec2 p = clamp(ivec2(floor((m - uOrigin) / uScale)), ivec2(0), size - 1);
    vec4 geom = texelFetch(uGeom, p, 0);
    vec4 frame = texelFetch(uFrame, p, 0);
    int flag = int(geom.w + 0.5);
    vec3 n = geom.xyz;
    vec3 c = vec3(0.0);
    if (uView == 0) {
        if (uModel == 2) {
            if (flag > 0) {
                c = srgb3(estimateShade(n, frame, uLight) * uGain);
            }
        } else if (flag >= 2) {
            vec4 kd = texelFetch(uKd, p, 0);
            vec4 ks = texelFetch(uKs, p, 0);
            // The half floats are near unit length; renormalise, and keep t perpendicular to n.
            n = normalize(n);
            vec3 t = normalize(frame.xyz - dot(frame.xyz, n) * n);
            t = editedTangent(t, n, frame.w);
            vec3 rad = uModel == 1 || flag == 3
                ? uIntensity * gltf(n, t, min(kd.rgb * uDiffuse, 1.0), kd.a,
                                    min(ks.r * uRoughness, 1.0), frame.w > 0.5 ? ks.g : 0.0,
                                    uLight)
                : ward(n, t, kd.rgb * uDiffuse, ks.rgb * uSpecular,
                       kd.a * uRoughness, ks.a * uRoughness, uLight);
            c = srgb3(rad * uGain);
        }
    } else if (uView == 9) {
        c = srgb3(samplesShade(p, normalize(uLight)) * uGain);
    } else if (uView == 1) {
        // symframe_io's normal picture, OpenGL convention: (n + 1) / 2.
        c = flag > 0 ? (n + 1.0) * 0.5 : vec3(0.0);
    } else if (uView == 2) {
        if (frame.w > 0.5) {
            vec3 t = flag >= 2 || uModel == 2 ? editedTangent(frame.xyz, normalize(n), frame.w)
                                              : frame.xyz;
            c = hue(2.0 * atan(t.y, t.x) / (2.0 * PI));
        }
    } else if (uView == 8) {
        // The glTF fit's base_color.png: clamped, sRGB-encoded, with the diffuse factor.
        if (flag >= 2) {
            c = srgb3(texelFetch(uKd, p, 0).rgb * uDiffuse);
        }
    } else if (uView == 3 || uView == 4) {
        // The albedo pictures (kd.png, ks.png): clamped, sRGB-encoded, with the edits' factors.
        if (flag >= 2) {
            c = uView == 3 ? srgb3(texelFetch(uKd, p, 0).rgb * uDiffuse)
                           : srgb3(texelFetch(uKs, p, 0).rgb * uSpecular);
        }
    } else if (uView >= 5 && uView <= 7) {
        vec4 est = texelFetch(uEst, p, 0);
        int has = int(est.w + 0.5);
        // Confidence and anisotropy are in [0, 1]: viridis over it, as confidence.png.
        if (uView == 5 && (has & 1) != 0) {
            c = viridis(est.x);
        } else if (uView == 6 && (has & 2) != 0) {
            c = viridis(est.y);
        } else if (uView == 7 && (has & 4) != 0) {
            // symframe_io's SOURCE_PALETTE.
            int code = int(est.z + 0.5);
            c = code == 0 ? vec3(0.0)
              : code == 1 ? vec3(31.0, 119.0, 180.0) / 255.0
              : code == 2 ? vec3(255.0, 127.0, 14.0) / 255.0
              : code == 3 ? vec3(44.0, 160.0, 44.0) / 255.0
              : code == 4 ? vec3(148.0, 103.0, 189.0) / 255.0
              : vec3(1.0, 0.0, 1.0);
        }
    }
    outColor = vec4(c, 1.0);
}
