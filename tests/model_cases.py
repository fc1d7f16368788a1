"""Representative model specs for every family, shared by the statistical and property tests.

``CASES`` maps a family name (as registered in ``brdf.models.MODELS``) to specs that cover its
options: isotropic and anisotropic lobes, every choice value, every Fresnel term, per-channel
(RGB) parameters, and lobes from broad (alpha 1, exponent 1) to sharp (alpha 0.05, exponent
1000). ``SUMS`` holds mixtures, including delta lobes and multi-lobe Lafortune fits.
"""

CONDUCTOR_RGB = "conductor(eta=[0.2,0.92,1.1], k=[3.9,2.45,2.2])"  # gold-like, PBR 3rd ed. 8.2.1

CASES = {
    "lambert": [
        "lambert(albedo=0.5)",
        "lambert(albedo=[0.8,0.5,0.2])",
    ],
    "mirror": [
        "mirror",
        "mirror(reflectance=0.9, fresnel=dielectric(eta=1.5))",
        f"mirror(reflectance=[0.95,0.9,0.85], fresnel={CONDUCTOR_RGB})",
        "mirror(reflectance=0.7, fresnel=schlick(f0=0.04))",
    ],
    "phong": [
        "phong(ks=0.5, n=1)",
        "phong(ks=0.8, n=50)",
        "phong(ks=[0.5,0.4,0.3], n=1000)",
    ],
    "modified-phong": [
        "modified-phong(ks=0.6, n=1)",
        "modified-phong(ks=0.9, n=80)",
        "modified-phong(ks=[0.5,0.4,0.3], n=1000)",
    ],
    "blinn-phong": [
        "blinn-phong(ks=0.7, n=1, normalization=exact)",
        "blinn-phong(ks=0.5, n=200, normalization=exact)",
        "blinn-phong(ks=0.8, n=10, normalization=approx)",
        "blinn-phong(ks=[0.6,0.5,0.4], n=1000, normalization=approx)",
    ],
    "ward": [
        "ward(rho_s=0.3, alpha=0.3)",
        "ward(rho_s=0.5, alpha=0.05, alpha_y=0.25)",
        "ward(rho_s=0.4, alpha=0.5, variant=duer)",
        "ward(rho_s=[0.3,0.2,0.1], alpha=0.1, alpha_y=0.4, variant=duer)",
        "ward(rho_s=0.6, alpha=0.15, variant=gmd)",
        "ward(rho_s=0.8, alpha=0.6, alpha_y=0.2, variant=gmd)",
    ],
    "ggx": [
        "ggx(alpha=0.05)",
        "ggx(alpha=0.3, fresnel=schlick(f0=0.04))",
        "ggx(alpha=1, masking=height-correlated)",
        "ggx(alpha=0.1, alpha_y=0.4, fresnel=dielectric(eta=1.5))",
        "ggx(ks=[0.9,0.6,0.3], alpha=0.6, alpha_y=0.15, masking=height-correlated, "
        f"fresnel={CONDUCTOR_RGB})",
        "ggx(ks=0.8, alpha=0.2, masking=height-correlated, fresnel=schlick(f0=[0.9,0.6,0.3]))",
        "ggx(alpha=0.5, fresnel=conductor(eta=0.2, k=3))",
    ],
    "beckmann": [
        "beckmann(alpha=0.05)",
        "beckmann(alpha=0.3, fresnel=schlick(f0=0.04))",
        "beckmann(alpha=1, masking=height-correlated)",
        "beckmann(alpha=0.1, alpha_y=0.4, fresnel=dielectric(eta=1.5))",
        "beckmann(ks=[0.9,0.6,0.3], alpha=0.6, alpha_y=0.15, masking=height-correlated, "
        f"fresnel={CONDUCTOR_RGB})",
        "beckmann(alpha=0.2, masking=height-correlated, fresnel=dielectric(eta=[1.3,1.5,1.7]))",
        "beckmann(ks=0.7, alpha=0.5, fresnel=conductor(eta=1.2, k=6))",
    ],
    "lafortune": [
        "lafortune(cx=-1, cy=-1, cz=1, n=20)",
        "lafortune(cx=-0.9, cy=-0.9, cz=0.95, n=1000)",
        "lafortune(cx=0.6, cy=0.6, cz=0.8, n=3)",
        "lafortune(cx=-1, cy=-0.4, cz=0.8, n=15)",
        "lafortune(cx=[-1,-0.95,-0.9], cy=[-1,-0.95,-0.9], cz=[1,0.9,0.8], n=[30,20,10])",
    ],
    "ashikhmin-shirley": [
        "ashikhmin-shirley(rd=0.5, rs=0.05, nu=100)",
        "ashikhmin-shirley(rd=0.2, rs=0.6, nu=1000)",
        "ashikhmin-shirley(rd=0.3, rs=0.3, nu=1)",
        "ashikhmin-shirley(rd=[0.6,0.4,0.2], rs=0.1, nu=10, nv=500)",
        "ashikhmin-shirley(rd=0, rs=0.9, nu=200, nv=20)",
    ],
    "oren-nayar": [
        "oren-nayar(albedo=0.5, sigma=0)",
        "oren-nayar(albedo=0.8, sigma=0.3)",
        "oren-nayar(albedo=[0.7,0.5,0.3], sigma=1.2)",
    ],
}

SUMS = [
    "lambert(albedo=0.3) + ggx(alpha=0.2)",
    "lambert(albedo=[0.5,0.3,0.2]) + beckmann(alpha=0.1, alpha_y=0.3, fresnel=schlick(f0=0.04))",
    "lambert(albedo=0.4) + mirror(reflectance=0.5, fresnel=dielectric(eta=1.5))",
    "lambert(albedo=0.2) + ggx(alpha=0.05) + mirror(reflectance=0.1)",
    "lambert(albedo=0.4) + lafortune(cx=-1, cy=-1, cz=1, n=50) "
    "+ lafortune(cx=-0.5, cy=-0.5, cz=0.6, n=4)",
    "modified-phong(ks=0.2, n=5) + blinn-phong(ks=0.3, n=300)",
    "ward(rho_s=0.2, alpha=0.2, variant=gmd) + ggx(alpha=0.05, fresnel=" + CONDUCTOR_RGB + ")",
    "lambert(albedo=0.5) + phong(ks=0.3, n=100)",
    "ashikhmin-shirley(rd=0.4, rs=0.1, nu=50, nv=5) + ggx(alpha=0.6)",
]


def all_specs():
    """Every spec: ``(family, spec)`` pairs, with ``"sum"`` as the family of mixtures."""
    return [(family, spec) for family, specs in CASES.items() for spec in specs] + \
        [("sum", spec) for spec in SUMS]
