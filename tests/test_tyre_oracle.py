"""An independent NumPy Magic Formula 5.2 / 6.1 (test oracle, not library code).

A direct transcription of Pacejka (2012) §4.3.2 (4.E1–4.E78) with the MF-Tyre deviations the
library documents (diffsusp.tyre.mf6), written from the .tir file in SI (metres, N·m) with a plain
dict of coefficients and a different code path: no shared helpers, no JAX, scalar-safe NumPy.
"""

import numpy as np


def _p(tir, name, default=0.0):
    return float(tir[name]) if name in tir else default


def mf_numpy(tir, FZ, SL, SA, IA, VX, P, *, combined=True, phit=None, omega=None):
    """Forces [N] and moments [N·m] for inputs in SI (FZ N, SL -, SA rad, IA rad, VX m/s, P Pa),
    limit checks on, no α*. Returns (Fx, Fy, Mx, My, Mz) arrays. `phit` [1/m]: turn slip on
    (Pacejka 2012 §4.3.3, (4.75)-(4.106), the choices diffsusp.tyre.mf6 documents), with wheel
    spin `omega` [rad/s] (default: from VX, SL and the effective rolling radius, `spin_numpy`)."""
    g = lambda n, d=0.0: _p(tir, n, d)  # noqa: E731
    lam = lambda n: _p(tir, n, 1.0)  # noqa: E731
    fittyp = int(tir["FITTYP"])
    mf52 = fittyp in (5, 6, 52)
    FZ, SL, SA, IA, VX, P = np.broadcast_arrays(*(np.asarray(v, dtype=float)
                                                  for v in (FZ, SL, SA, IA, VX, P)))
    inf = np.inf
    FZ = np.where(FZ < 0, 0.0, FZ)
    uFZ = FZ.copy()
    uSL = SL.copy()
    FZ = np.minimum(FZ, g("FZMAX", inf))
    SL = np.minimum(np.maximum(SL, g("KPUMIN", -inf)), g("KPUMAX", inf))
    SA = np.minimum(np.maximum(SA, g("ALPMIN", -inf)), g("ALPMAX", inf))
    IA = np.minimum(np.maximum(IA, g("CAMMIN", -inf)), g("CAMMAX", inf))
    pmin, pmax = g("PRESMIN", -inf) or -inf, g("PRESMAX", inf) or inf
    P = np.minimum(np.maximum(P, pmin), pmax)
    FZMIN = g("FZMIN", 0.0)

    R0 = g("UNLOADED_RADIUS")
    FNOMIN = g("FNOMIN")
    Fz0p = FNOMIN * lam("LFZO")
    dfz = (FZ - Fz0p) / Fz0p
    p0 = g("NOMPRES", 0.0) or g("INFLPRES", 1.0)
    dpi = np.zeros_like(FZ) if mf52 else (P - p0) / p0
    eps = 1e-6
    sg = lambda x: np.where(x < 0, -1.0, 1.0)  # noqa: E731
    ts = phit is not None
    if ts:
        if omega is None:
            omega = spin_numpy(tir, uFZ, VX, uSL, P)
        # (4.75)-(4.76): psi_dot = -phit*Vc, phi = -(psi_dot - (1 - eps_g)*Omega*sin(gamma))/Vc
        phit_a = np.asarray(phit, dtype=float) * np.cos(SA)  # MFeval: phit*cos(alpha)
        Vc = VX / np.abs(np.cos(SA))
        psi_dot = -phit_a * Vc
        eps_g = g("PECP1") * (1 + g("PECP2") * dfz)
        phi = -(psi_dot - (1 - eps_g) * omega * np.sin(IA)) / Vc
        zeta1 = np.cos(np.arctan(g("PDXP1") * (1 + g("PDXP2") * dfz)
                                 * np.cos(np.arctan(g("PDXP3") * SL)) * R0 * phi))
        zeta3 = np.cos(np.arctan(g("PKYP1") * R0 ** 2 * phi ** 2))
        Byp = g("PDYP1") * (1 + g("PDYP2") * dfz) * np.cos(np.arctan(g("PDYP3") * np.tan(SA)))
        zeta2 = np.cos(np.arctan(Byp * (R0 * np.abs(phi)
                                        + g("PDYP4") * np.sqrt(R0 * np.abs(phi)))))
        zeta5 = np.cos(np.arctan(g("QDTP1") * R0 * phi))
        zeta6 = np.cos(np.arctan(g("QBRP1") * R0 * phi))
    else:
        zeta1 = zeta2 = zeta3 = zeta5 = zeta6 = 1.0

    # ---- Fx0 (4.E9-4.E18)
    Cx = g("PCX1") * lam("LCX")
    mux = ((g("PDX1") + g("PDX2") * dfz) * (1 + g("PPX3") * dpi + g("PPX4") * dpi ** 2)
           * (1 - g("PDX3") * IA ** 2) * lam("LMUX"))
    Dx = mux * FZ * zeta1
    Kxk = (FZ * (g("PKX1") + g("PKX2") * dfz) * np.exp(g("PKX3") * dfz)
           * (1 + g("PPX1") * dpi + g("PPX2") * dpi ** 2) * lam("LKX"))
    Bx = Kxk / (Cx * Dx + eps * sg(Dx))
    SHx = (g("PHX1") + g("PHX2") * dfz) * lam("LHX")
    SVx = FZ * (g("PVX1") + g("PVX2") * dfz) * lam("LVX") * lam("LMUX")
    kx = SL + SHx
    Ex = np.minimum((g("PEX1") + g("PEX2") * dfz + g("PEX3") * dfz ** 2)
                    * (1 - g("PEX4") * np.sign(kx)) * lam("LEX"), 1.0)
    Fx0 = Dx * np.sin(Cx * np.arctan(Bx * kx - Ex * (Bx * kx - np.arctan(Bx * kx)))) + SVx

    # ---- Fy0 (4.E19-4.E30), as a function of camber
    def fy0(gam, ts=False):
        z2, z3 = (zeta2, zeta3) if ts else (1.0, 1.0)
        if mf52:
            Kya = (g("PKY1") * Fz0p * np.sin(g("PKY4", 2.0) * np.arctan(FZ / (g("PKY2") * Fz0p)))
                   * (1 - g("PKY3") * np.abs(gam)) * lam("LKY"))
            SHy = (g("PHY1") + g("PHY2") * dfz) * lam("LHY") + g("PHY3") * gam * lam("LKYC")
            SVyg = FZ * (g("PVY3") + g("PVY4") * dfz) * gam * lam("LKYC") * lam("LMUY")
        else:
            Kya = (g("PKY1") * Fz0p * (1 + g("PPY1") * dpi) * (1 - g("PKY3") * np.abs(gam))
                   * np.sin(g("PKY4", 2.0) * np.arctan(FZ / Fz0p / ((g("PKY2")
                                                            + g("PKY5") * gam ** 2)
                                                            * (1 + g("PPY2") * dpi))))
                   * lam("LKY")) * z3
            Kyg0 = FZ * (g("PKY6") + g("PKY7") * dfz) * (1 + g("PPY5") * dpi) * lam("LKYC")
            SVyg = FZ * (g("PVY3") + g("PVY4") * dfz) * gam * lam("LKYC") * lam("LMUY") * z2
            if ts:  # zeta0 = 0, zeta4 (4.80-4.89)
                Kya0 = (g("PKY1") * Fz0p * (1 + g("PPY1") * dpi)
                        * np.sin(g("PKY4", 2.0) * np.arctan(FZ / Fz0p / (g("PKY2")
                                                                        * (1 + g("PPY2") * dpi))))
                        * lam("LKY")) * z3
                CH, DH = g("PHYP1", 1.0), g("PHYP2") + g("PHYP3") * dfz
                EH = min(g("PHYP4"), 1.0)
                den = CH * DH * (Kya0 + eps * sg(Kya0))
                BH = Kyg0 / (1 - eps_g) / (den + eps * sg(den))
                x = BH * R0 * phi
                SHyp = DH * np.sin(CH * np.arctan(x - EH * (x - np.arctan(x))))
                zeta4 = 1 + SHyp - SVyg / (Kya + eps * sg(Kya))
                SHy = (g("PHY1") + g("PHY2") * dfz) * lam("LHY") + zeta4 - 1
            else:
                SHy = ((g("PHY1") + g("PHY2") * dfz) * lam("LHY")
                       + (Kyg0 * gam - SVyg) / (Kya + eps * sg(Kya)))
        SVy = FZ * (g("PVY1") + g("PVY2") * dfz) * lam("LVY") * lam("LMUY") * z2 + SVyg
        ay = SA + SHy
        Cy = g("PCY1") * lam("LCY")
        muy = ((g("PDY1") + g("PDY2") * dfz) * (1 + g("PPY3") * dpi + g("PPY4") * dpi ** 2)
               * (1 - g("PDY3") * gam ** 2) * lam("LMUY"))
        Dy = muy * FZ * z2
        Ey = np.minimum((g("PEY1") + g("PEY2") * dfz)
                        * (1 + g("PEY5") * gam ** 2 - (g("PEY3") + g("PEY4") * gam) * sg(ay))
                        * lam("LEY"), 1.0)
        By = Kya / (Cy * Dy + eps * sg(Dy))
        F = Dy * np.sin(Cy * np.arctan(By * ay - Ey * (By * ay - np.arctan(By * ay)))) + SVy
        return F, dict(Kya=Kya, SHy=SHy, SVy=SVy, By=By, Cy=Cy, muy=muy)

    Fy0, v = fy0(IA, ts)
    Fy0g0, _ = fy0(np.zeros_like(IA))

    # ---- Mz0 (4.E31-4.E49 with A58, A60)
    Fzm = np.where(FZ <= 0, 0.0, np.maximum(FZ, FZMIN))
    Kyap = v["Kya"] + eps * sg(v["Kya"])
    ar = SA + v["SHy"] + v["SVy"] / Kyap
    at = SA + g("QHZ1") + g("QHZ2") * dfz + (g("QHZ3") + g("QHZ4") * dfz) * IA
    Dt = ((g("QDZ1") + g("QDZ2") * dfz) * (1 - g("PPZ1") * dpi)
          * (1 + g("QDZ3") * IA + g("QDZ4") * IA ** 2) * Fzm * (R0 / Fz0p) * lam("LTR")) * zeta5
    Bt = ((g("QBZ1") + g("QBZ2") * dfz + g("QBZ3") * dfz ** 2)
          * (1 + g("QBZ4") * IA + g("QBZ5") * np.abs(IA)) * lam("LKY") / lam("LMUY"))
    Ct = g("QCZ1")
    Et = np.minimum((g("QEZ1") + g("QEZ2") * dfz + g("QEZ3") * dfz ** 2)
                    * (1 + (g("QEZ4") + g("QEZ5") * IA) * (2 / np.pi) * np.arctan(Bt * Ct * at)),
                    1.0)
    Vc = np.sqrt(VX ** 2 + (np.tan(SA) * VX) ** 2)
    cosap = np.cos(np.arccos(VX / (Vc + eps)))
    zeta0 = 0.0 if ts else 1.0
    Dr = (Fzm * R0 * ((g("QDZ6") + g("QDZ7") * dfz) * lam("LRES") * zeta2
                      + ((g("QDZ8") + g("QDZ9") * dfz) * (1 + g("PPZ2") * dpi)
                         + (g("QDZ10") + g("QDZ11") * dfz) * np.abs(IA)) * IA * lam("LKZC")
                      * zeta0)
          * lam("LMUY") * np.cos(SA))
    Br = (g("QBZ9") * lam("LKY") / lam("LMUY") + g("QBZ10") * v["By"] * v["Cy"]) * zeta6
    Cr = lambda Gyk: 1.0  # noqa: E731
    if ts:  # zeta7, zeta8 (4.93-4.103)
        Mzinf = np.maximum(g("QCRP1") * np.abs(v["muy"]) * R0 * Fzm * np.sqrt(Fzm / Fz0p)
                           * lam("LMP"), 1e-6)
        CD = g("QDRP1", 1.0)
        DD = Mzinf / np.sin(0.5 * np.pi * CD)
        Kzgr0 = (Fzm * R0 * (g("QDZ8") + g("QDZ9") * dfz) * (1 + g("PPZ2") * dpi)
                 * lam("LKZC") * lam("LMUY"))
        BD = Kzgr0 / (CD * DD * (1 - eps_g))
        Drp = DD * np.sin(CD * np.arctan(BD * R0 * phi))
        Dr = Dr + Drp  # zeta8 - 1

        def Cr(Gyk):  # noqa: F811
            Mz90 = Mzinf * (2 / np.pi) * np.arctan(g("QCRP2") * R0 * np.abs(phit_a)) * Gyk
            return (2 / np.pi) * np.arccos(np.clip(Mz90 / np.maximum(np.abs(Drp), 1e-15), -1, 1))

    def trail(a):
        return Dt * np.cos(Ct * np.arctan(Bt * a - Et * (Bt * a - np.arctan(Bt * a)))) * cosap

    if not combined:
        Mz0 = -trail(at) * Fy0g0 + Dr * np.cos(Cr(1.0) * np.arctan(Br * ar)) * cosap
        Fx, Fy, Mz = Fx0, Fy0, Mz0
    else:
        # ---- Fx (4.E50-4.E57)
        Bxa = ((g("RBX1") + (0.0 if mf52 else g("RBX3") * IA ** 2))
               * np.cos(np.arctan(g("RBX2") * SL)) * lam("LXAL"))
        Cxa, Exa, SHxa = g("RCX1"), np.minimum(g("REX1") + g("REX2") * dfz, 1.0), g("RHX1")
        G = lambda B, C, E, x: np.cos(C * np.arctan(B * x - E * (B * x - np.arctan(B * x))))  # noqa
        Fx = G(Bxa, Cxa, Exa, SA + SHxa) / G(Bxa, Cxa, Exa, SHxa) * Fx0
        # ---- Fy (4.E58-4.E67)
        DVyk = (v["muy"] * FZ * (g("RVY1") + g("RVY2") * dfz + g("RVY3") * IA)
                * np.cos(np.arctan(g("RVY4") * SA)))
        SVyk = DVyk * np.sin(g("RVY5") * np.arctan(g("RVY6") * SL)) * lam("LVYKA")
        SHyk = g("RHY1") + g("RHY2") * dfz
        Eyk = np.minimum(g("REY1") + g("REY2") * dfz, 1.0)
        Byk = ((g("RBY1") + (0.0 if mf52 else g("RBY4") * IA ** 2))
               * np.cos(np.arctan(g("RBY2") * (SA - g("RBY3")))) * lam("LYKA"))
        Gyk = G(Byk, g("RCY1"), Eyk, SL + SHyk) / G(Byk, g("RCY1"), Eyk, SHyk)
        Fy = Gyk * Fy0 + SVyk
        # ---- Mz (4.E71-4.E78 with A54-A56)
        r = (Kxk / Kyap) ** 2 * SL ** 2
        ar_eq = np.arctan(np.sqrt(np.tan(ar) ** 2 + r)) * np.sign(ar)
        at_eq = np.arctan(np.sqrt(np.tan(at) ** 2 + r)) * np.sign(at)
        s = R0 * (g("SSZ1") + g("SSZ2") * Fy / FNOMIN + (g("SSZ3") + g("SSZ4") * dfz) * IA) \
            * lam("LS")
        t = trail(at_eq) * lam("LFZO")
        Mzr = Dr * np.cos(Cr(Gyk) * np.arctan(Br * ar_eq))
        Fyp = (Fy - SVyk) if mf52 else Gyk * Fy0g0
        Mz = -t * Fyp + Mzr + s * Fx

    # ---- Mx
    Fzx = np.where(FZ < FZMIN, FZ * (FZ / FZMIN) ** 2, FZ) if FZMIN > 0 else FZ
    if mf52:
        Mx = R0 * Fzx * (g("QSX1") * lam("LVMX") - g("QSX2") * IA + g("QSX3") * Fy / FNOMIN) \
            * lam("LMX")
    else:
        Mx = (R0 * Fzx * lam("LMX") * (
            g("QSX1") * lam("LVMX") - g("QSX2") * IA * (1 + g("PPMX1") * dpi)
            - g("QSX12") * IA * np.abs(IA) + g("QSX3") * Fy / FNOMIN
            + g("QSX4") * np.cos(g("QSX5") * np.arctan((g("QSX6") * Fzx / FNOMIN) ** 2))
            * np.sin(g("QSX7") * IA + g("QSX8") * np.arctan(g("QSX9") * Fy / FNOMIN))
            + g("QSX10") * np.arctan(g("QSX11") * Fzx / FNOMIN) * IA)
            + R0 * Fy * lam("LMX") * (g("QSX13") + g("QSX14") * np.abs(IA)))
    # ---- My
    Fzy = np.where(uFZ < FZMIN, uFZ * uFZ / FZMIN, uFZ) if FZMIN > 0 else uFZ
    V0 = g("LONGVL", 16.7)
    base = (g("QSY1") + g("QSY2") * Fx / FNOMIN + g("QSY3") * np.abs(VX / V0)
            + g("QSY4") * (VX / V0) ** 4)
    if mf52:
        My = -R0 * Fzy * lam("LMY") * base
    else:
        My = -R0 * FNOMIN * lam("LMY") * (base + (g("QSY5") + g("QSY6") * Fzy / FNOMIN) * IA ** 2) \
            * (Fzy / FNOMIN) ** g("QSY7") * (P / p0) ** g("QSY8")
    return Fx, Fy, Mx, My, Mz


# ---- the vertical model (Besselink et al. 2010 eqs. (1)-(8), Pacejka 2012 (A3.3), the MF-Swift
# 6.2 vertical force as MFeval evaluates it), in SI


def _vc(tir, P):
    g = lambda n, d=0.0: _p(tir, n, d)  # noqa: E731
    mf52 = int(tir["FITTYP"]) in (5, 6, 52)
    p0 = g("NOMPRES", 0.0) or g("INFLPRES", 1.0)
    dpi = 0.0 * np.asarray(P, dtype=float) if mf52 else (np.asarray(P, dtype=float) - p0) / p0
    return g, dpi


def re_numpy(tir, FZ, OMEGA, P):
    """Free radius R_omega and effective rolling radius R_e [m]."""
    g, dpi = _vc(tir, P)
    R0, V0, Fz0 = g("UNLOADED_RADIUS"), g("LONGVL", 16.7), g("FNOMIN")
    Romega = R0 * (g("Q_RE0", 1.0) + g("Q_V1") * (OMEGA * R0 / V0) ** 2)
    Cz = g("VERTICAL_STIFFNESS") * (1 + g("PFZ1") * dpi)
    FZ = np.maximum(FZ, 0.0)
    return Romega, Romega - Fz0 / Cz * (g("DREFF") * np.arctan(g("BREFF") * FZ / Fz0)
                                        + g("FREFF") * FZ / Fz0)


def spin_numpy(tir, FZ, VX, SL, P):
    """Omega [rad/s] with SL = (Omega*R_e - VX)/VX, iterated to a fixed point (50 times)."""
    om = VX * (1 + SL) / _p(tir, "UNLOADED_RADIUS")
    for _ in range(50):
        om = VX * (1 + SL) / re_numpy(tir, FZ, om, P)[1]
    return om


def fz_numpy(tir, RL, FX, FY, IA, OMEGA, P):
    """Vertical force [N] at loaded radius RL [m] (scalar inputs)."""
    g, dpi = _vc(tir, P)
    R0, V0, Fz0 = g("UNLOADED_RADIUS"), g("LONGVL", 16.7), g("FNOMIN")
    Romega = re_numpy(tir, 0.0, OMEGA, P)[0]
    qfz2 = g("Q_FZ2")
    qfz1 = np.sqrt((g("VERTICAL_STIFFNESS") * R0 / Fz0) ** 2 - 4 * qfz2)
    rfr = max(Romega - RL, 0.0)
    if int(tir["FITTYP"]) == 62:
        sfyg = (g("Q_FYS1") + g("Q_FYS2") * RL / Romega + g("Q_FYS3") * (RL / Romega) ** 2) * IA
        rtw = (1.075 - 0.5 * g("ASPECT_RATIO")) * g("WIDTH")
        k = ((g("Q_CAM1") * RL + g("Q_CAM2") * RL ** 2)
             / (g("Q_CAM1") * Romega + g("Q_CAM2") * Romega ** 2))
        rho = max(rfr + k ** 2 * rtw / 8 * abs(np.tan(IA)) - g("Q_CAM3") * rfr * abs(IA), 1e-15)
        side = ((rho / R0) ** g("Q_FCY2") * g("Q_FCY") * (FY - sfyg) / Fz0) ** 2
    else:
        rho, side = rfr, (g("Q_FCY") * FY / Fz0) ** 2
    corr = (1 + g("Q_V2") * R0 / V0 * abs(OMEGA) - (g("Q_FCX") * FX / Fz0) ** 2 - side) \
        * (1 + g("PFZ1") * dpi)
    return corr * (qfz1 * rho / R0 + qfz2 * (rho / R0) ** 2) * Fz0
