# The single-ray kernel for incoherent rays (AVX2 and AVX-512 machines), written by hand (see
# asm.rs for why and for the layout of the `AsmRay` it reads and writes). Two functions, one
# per query kind, made by the macro `MRK_WALK`: `megaray_walk_closest` and `megaray_walk_any`,
# called with the AsmRay in rdi and the `Ray` in rsi. Each makes the ray's constants as
# `RayBox::new` and `RayTri4::with_axis_avx` make them (the same operations), then does for the
# new ray on a tracer whose every tile is checked what `Tracer::walk` does (the same operations
# in the same order, so the same hits bit for bit: tests compare them), and returns an event
# code: 0 the stack ran empty (the ray is done), 1 an any-hit query found a hit, 2 an edge lies
# exactly on the ray (`Event::Exact`), 3 the fixed stack is full (`Event::Full`).
#
# Registers, after the set-up:
#   rdi      the AsmRay                    rsi      the stack pointer (next free Entry)
#   r8-r10   near rows x, y, z             r11-r13  far rows x, y, z
#            (each: the pool's address plus the row's byte offset in a node)
#   r14      the pool (the mapped file)    rax      the reference being visited
#   ymm0-2   the origin                    ymm3-5   -1/d
#   ymm6-8   -FAR_EPS/d                    ymm9     t_min
#   ymm10    the closest hit times FAR_EPS (its low lane the scalar the pops compare with)
#   rbx rbp r15 rcx rdx, ymm11-15: scratch. A leaf test takes ymm0-8 and ymm10 as well and
#   reloads them after the leaf (MRK_RELOAD: from the frame, the closest hit from the AsmRay).
#
# Operands in braces are Rust constants (`global_asm!` in asm.rs): the AsmRay's field offsets,
# that of a node's child references, FAR_EPS and TINY as bits.

# The machine stack frame (rsp aligned to 32 bytes).
.set MRK_F_NEAR, 0          # the box test's entry distances (8 floats)
.set MRK_F_OKX, 32          # the triangle test's splats: origin permuted (kx, ky, kz),
.set MRK_F_OKY, 64          #   shear (sx, sy, sz), t_min; 8 floats each
.set MRK_F_OKZ, 96
.set MRK_F_SX, 128
.set MRK_F_SY, 160
.set MRK_F_SZ, 192
.set MRK_F_TMIN, 224
.set MRK_F_T, 256           # a leaf test's t, v, w and 1/det of its eight lanes
.set MRK_F_V, 288
.set MRK_F_W, 320
.set MRK_F_I, 352
.set MRK_F_ONE, 384         # 1.0 in eight lanes
.set MRK_F_STACK, 416       # the stack's first entry
.set MRK_F_LIMIT, 424       # the stack pointer past which a node's children may not fit
.set MRK_F_UNIT, 432        # the leaf's next block (offset / 16)
.set MRK_F_LEFT, 440        # its triangles from there
.set MRK_F_SAVED, 448      # rsp before the frame was aligned
.set MRK_F_HIGH, 456        # an any-hit walk's order: 1 from the last slot down (`FAR_HIGH`; any-hit only)
.set MRK_F_ORG, 464         # the origin, -1/d and -FAR_EPS/d (four lanes each, for MRK_RELOAD)
.set MRK_F_NINV, 480
.set MRK_F_NINVF, 496
.set MRK_F_KB, 512          # the triangle rows' offsets kx, ky, kz (three quadwords)
.set MRK_FRAME, 544

# The nine broadcasts of the box test's constants and that of the closest hit (widened).
.macro MRK_RELOAD
    vbroadcastss ymm0, dword ptr [rsp + MRK_F_ORG]
    vbroadcastss ymm1, dword ptr [rsp + MRK_F_ORG + 4]
    vbroadcastss ymm2, dword ptr [rsp + MRK_F_ORG + 8]
    vbroadcastss ymm3, dword ptr [rsp + MRK_F_NINV]
    vbroadcastss ymm4, dword ptr [rsp + MRK_F_NINV + 4]
    vbroadcastss ymm5, dword ptr [rsp + MRK_F_NINV + 8]
    vbroadcastss ymm6, dword ptr [rsp + MRK_F_NINVF]
    vbroadcastss ymm7, dword ptr [rsp + MRK_F_NINVF + 4]
    vbroadcastss ymm8, dword ptr [rsp + MRK_F_NINVF + 8]
    vbroadcastss ymm10, dword ptr [rdi + {t_wide}]
.endm

# An any-hit walk's push of the node's child in slot rbp (its references at rdx): the
# reference, the tile `TOP` (-1), no entry distance (an any-hit walk reads none), and the
# child asked for (`MRK_PREFETCH`). Clobbers r15, rax and rbp.
.macro MRK_PUSH_ANY
    mov r15, qword ptr [rdx + 8 * rbp]
    mov qword ptr [rsi], r15
    mov dword ptr [rsi + 8], -1
    add rsi, 16
    MRK_PREFETCH r15, rax, rbp
.endm

# `Tracer::prefetch` of reference `r`, a child just pushed: a node's four lines, or a leaf's
# first 256 bytes and, when it has more than four triangles, the rest of its second block
# (what `Tracer::prefetch` asks for, but without branches: the kind of a child pushed is as
# good as random). Clobbers `off` and `cnt`.
.macro MRK_PREFETCH r, off, cnt
    mov \off, \r
    shl \off, 28
    shr \off, 20                       # a node's offset
    mov \cnt, \r
    shl \cnt, 24
    shr \cnt, 20                       # a leaf's
    bt \r, 62
    cmovc \off, \cnt
    prefetcht0 byte ptr [r14 + \off]
    prefetcht0 byte ptr [r14 + \off + 64]
    prefetcht0 byte ptr [r14 + \off + 128]
    prefetcht0 byte ptr [r14 + \off + 192]
    # A leaf of more than four triangles: the rest of its second block (else line 0 again).
    # Bits 40.. of a leaf hold 0x400000 | count; of an inner node 0; of a link above 0x7fffff.
    mov \cnt, \r
    shr \cnt, 40
    and \cnt, 0xc000ff
    sub \cnt, 0x400005
    cmp \cnt, 0x3ffffb
    lea \cnt, [\off + 256]
    cmovnc \cnt, \off
    prefetcht0 byte ptr [r14 + \cnt]
    prefetcht0 byte ptr [r14 + \cnt + 31]
.endm

# A triangle row of the leaf's block(s) at rax: corner `c`'s axis `k` (a register holding
# 0, 16 or 32), four lanes (`w` 4) or eight, the second block's four high (`w` 8).
.macro MRK_ROW dst, k, c, w
.if \w == 8
    vmovups xmm\dst, xmmword ptr [rax + \k + 48 * \c]
    vinsertf128 ymm\dst, ymm\dst, xmmword ptr [rax + \k + 48 * \c + 144], 1
.else
    vmovups xmm\dst, xmmword ptr [rax + \k + 48 * \c]
.endif
.endm

# The watertight test of the leaf's block(s) at rax (`w` 4: one block, lanes in ecx; 8: two),
# `RayTri4::test_k` / `test8_k` with the rows by the ray's axes, operation for operation.
# Row offsets: rbx kx, rbp ky, r15 kz. Jumps to `miss` when no lane hits, to `exact` when an
# edge of a lane in ecx lies on the ray; falls through with the nearest lane's number in edx
# and its t, v, w, 1/det in the frame.
.macro MRK_TRI w, v, any, miss, exact
    MRK_ROW 0, r15, 0, \w
    vsubps \v\()0, \v\()0, \v\()word ptr [rsp + MRK_F_OKZ]       # az
    MRK_ROW 1, r15, 1, \w
    vsubps \v\()1, \v\()1, \v\()word ptr [rsp + MRK_F_OKZ]       # bz
    MRK_ROW 2, r15, 2, \w
    vsubps \v\()2, \v\()2, \v\()word ptr [rsp + MRK_F_OKZ]       # cz
    MRK_ROW 3, rbx, 0, \w
    vsubps \v\()3, \v\()3, \v\()word ptr [rsp + MRK_F_OKX]
    vmulps \v\()11, \v\()0, \v\()word ptr [rsp + MRK_F_SX]
    vsubps \v\()3, \v\()3, \v\()11                                # ax
    MRK_ROW 4, rbp, 0, \w
    vsubps \v\()4, \v\()4, \v\()word ptr [rsp + MRK_F_OKY]
    vmulps \v\()11, \v\()0, \v\()word ptr [rsp + MRK_F_SY]
    vsubps \v\()4, \v\()4, \v\()11                                # ay
    MRK_ROW 5, rbx, 1, \w
    vsubps \v\()5, \v\()5, \v\()word ptr [rsp + MRK_F_OKX]
    vmulps \v\()11, \v\()1, \v\()word ptr [rsp + MRK_F_SX]
    vsubps \v\()5, \v\()5, \v\()11                                # bx
    MRK_ROW 6, rbp, 1, \w
    vsubps \v\()6, \v\()6, \v\()word ptr [rsp + MRK_F_OKY]
    vmulps \v\()11, \v\()1, \v\()word ptr [rsp + MRK_F_SY]
    vsubps \v\()6, \v\()6, \v\()11                                # by
    MRK_ROW 7, rbx, 2, \w
    vsubps \v\()7, \v\()7, \v\()word ptr [rsp + MRK_F_OKX]
    vmulps \v\()11, \v\()2, \v\()word ptr [rsp + MRK_F_SX]
    vsubps \v\()7, \v\()7, \v\()11                                # cx
    MRK_ROW 8, rbp, 2, \w
    vsubps \v\()8, \v\()8, \v\()word ptr [rsp + MRK_F_OKY]
    vmulps \v\()11, \v\()2, \v\()word ptr [rsp + MRK_F_SY]
    vsubps \v\()8, \v\()8, \v\()11                                # cy
    vmulps \v\()11, \v\()7, \v\()6
    vmulps \v\()12, \v\()8, \v\()5
    vsubps \v\()11, \v\()11, \v\()12                              # u = cx by - cy bx
    vmulps \v\()12, \v\()3, \v\()8
    vmulps \v\()13, \v\()4, \v\()7
    vsubps \v\()12, \v\()12, \v\()13                              # v = ax cy - ay cx
    vmulps \v\()13, \v\()5, \v\()4
    vmulps \v\()14, \v\()6, \v\()3
    vsubps \v\()13, \v\()13, \v\()14                              # w = bx ay - by ax
    vxorps xmm14, xmm14, xmm14
    vcmpeqps \v\()3, \v\()11, \v\()14
    vcmpeqps \v\()4, \v\()12, \v\()14
    vorps \v\()3, \v\()3, \v\()4
    vcmpeqps \v\()4, \v\()13, \v\()14
    vorps \v\()3, \v\()3, \v\()4
    vmovmskps edx, \v\()3
    test edx, ecx
    jnz \exact                                                    # an edge on the ray
    vxorps \v\()3, \v\()11, \v\()12
    vxorps \v\()4, \v\()11, \v\()13
    vorps \v\()3, \v\()3, \v\()4
    vmovmskps edx, \v\()3
    andn ecx, edx, ecx                                            # inside: signs agree
    # (No branch on it: whether a lane is inside is as good as random, and the test of the
    # distances below costs less than the mispredictions.)
    vaddps \v\()3, \v\()11, \v\()12
    vaddps \v\()3, \v\()3, \v\()13                                # det = u + v + w
    vmulps \v\()0, \v\()0, \v\()word ptr [rsp + MRK_F_SZ]
    vmulps \v\()0, \v\()11, \v\()0
    vmulps \v\()1, \v\()1, \v\()word ptr [rsp + MRK_F_SZ]
    vmulps \v\()1, \v\()12, \v\()1
    vaddps \v\()0, \v\()0, \v\()1
    vmulps \v\()2, \v\()2, \v\()word ptr [rsp + MRK_F_SZ]
    vmulps \v\()2, \v\()13, \v\()2
    vaddps \v\()0, \v\()0, \v\()2                                 # t_scaled
    vmovaps \v\()4, \v\()word ptr [rsp + MRK_F_ONE]
    vdivps \v\()4, \v\()4, \v\()3                                 # 1 / det
    vmulps \v\()0, \v\()0, \v\()4                                 # t
    vcmpps \v\()1, \v\()0, \v\()word ptr [rsp + MRK_F_TMIN], 13   # t >= t_min
    vbroadcastss \v\()2, dword ptr [rdi + {t_best}]
    vcmpps \v\()2, \v\()0, \v\()2, 1                              # t < t_max
    vandps \v\()1, \v\()1, \v\()2
    vmovmskps edx, \v\()1
    and ecx, edx
    jz \miss
.if \any && \w == 8
    # The hit two single-block tests would stop at: the first block's nearest.
    test ecx, 0xf
    jz 5f
    and ecx, 0xf
5:
.endif
    vmovaps \v\()word ptr [rsp + MRK_F_T], \v\()0
    vmovaps \v\()word ptr [rsp + MRK_F_V], \v\()12
    vmovaps \v\()word ptr [rsp + MRK_F_W], \v\()13
    vmovaps \v\()word ptr [rsp + MRK_F_I], \v\()4
    tzcnt edx, ecx
    blsr ecx, ecx
    jz 7f
6:
    tzcnt eax, ecx
    blsr ecx, ecx
    vmovss xmm1, dword ptr [rsp + MRK_F_T + 4 * rdx]
    vucomiss xmm1, dword ptr [rsp + MRK_F_T + 4 * rax]
    cmova edx, eax                                                # a nearer lane
    test ecx, ecx
    jnz 6b
7:
.endm

# The hit in lane edx of the leaf's block(s) made the closest (`Tracer::walk`'s update of
# `t_best`, `t_wide` and `best`).
.macro MRK_RECORD
    vmovss xmm1, dword ptr [rsp + MRK_F_T + 4 * rdx]
    vmovss xmm2, dword ptr [rsp + MRK_F_I + 4 * rdx]
    vmulss xmm3, xmm2, dword ptr [rsp + MRK_F_V + 4 * rdx]
    vmulss xmm2, xmm2, dword ptr [rsp + MRK_F_W + 4 * rdx]
    vmovss dword ptr [rdi + {t_best}], xmm1
    vmulss xmm1, xmm1, dword ptr [rip + .Lmrk_far_eps]
    vmovss dword ptr [rdi + {t_wide}], xmm1
    vmovss dword ptr [rdi + {u}], xmm3
    vmovss dword ptr [rdi + {v}], xmm2
    mov eax, edx
    and eax, 3
    mov dword ptr [rdi + {lane}], eax
    shr edx, 2
    lea rdx, [rdx + 8 * rdx]
    add rdx, qword ptr [rsp + MRK_F_UNIT]
    mov qword ptr [rdi + {unit}], rdx
    mov dword ptr [rdi + {found}], 1
.endm

.macro MRK_WALK name, any
    .globl \name
    .p2align 6
\name:
    push rbp
    push rbx
    push r12
    push r13
    push r14
    push r15
    mov rax, rsp
    and rsp, -32
    sub rsp, MRK_FRAME
    mov qword ptr [rsp + MRK_F_SAVED], rax
    # The ray's constants (`RayBox::new`): 1 / d with components of nearly zero made +-1e-20,
    # -1/d, -FAR_EPS/d, the plane rows of its octant.
    # Read field by field (`Ray::settled`): a ray written just before the call is taken from
    # the pending stores, where a 16-byte load spanning them would wait for the cache.
    vmovss xmm0, dword ptr [rsi]                    # ox
    vinsertps xmm0, xmm0, dword ptr [rsi + 4], 0x10
    vinsertps xmm0, xmm0, dword ptr [rsi + 8], 0x20
    vinsertps xmm0, xmm0, dword ptr [rsi + 8], 0x30 # ox oy oz oz
    vmovss xmm1, dword ptr [rsi + 12]               # dx
    vinsertps xmm1, xmm1, dword ptr [rsi + 16], 0x10
    vinsertps xmm1, xmm1, dword ptr [rsi + 20], 0x20
    vinsertps xmm1, xmm1, dword ptr [rsi + 20], 0x30 # dx dy dz dz
    vandps xmm2, xmm1, xmmword ptr [rip + .Lmrk_abs]
    vmaxps xmm3, xmm2, xmmword ptr [rip + .Lmrk_tiny]
    vandps xmm4, xmm1, xmmword ptr [rip + .Lmrk_sign]
    vorps xmm3, xmm3, xmm4
    vmovaps xmm5, xmmword ptr [rip + .Lmrk_one]
    vdivps xmm5, xmm5, xmm3                         # inv
    vxorps xmm6, xmm5, xmmword ptr [rip + .Lmrk_sign]
    vmulps xmm7, xmm6, xmmword ptr [rip + .Lmrk_far_eps]
    vmovaps xmmword ptr [rsp + MRK_F_ORG], xmm0
    vmovaps xmmword ptr [rsp + MRK_F_NINV], xmm6
    vmovaps xmmword ptr [rsp + MRK_F_NINVF], xmm7
    mov r14, qword ptr [rdi + {pool}]
    vmovmskps eax, xmm1                             # the octant's bits
.if \any
    # `FAR_HIGH` (read by any-hit walks only): at most one negative (bit 3 is z's again).
    mov ecx, eax
    and ecx, 7
    popcnt ecx, ecx
    cmp ecx, 1
    setbe cl
    mov byte ptr [rsp + MRK_F_HIGH], cl
.endif
    mov ecx, eax
    and ecx, 1
    shl ecx, 5
    lea r8, [r14 + rcx]
    xor ecx, 32
    lea r11, [r14 + rcx]
    mov ecx, eax
    and ecx, 2
    shl ecx, 4
    lea r9, [r14 + rcx + 64]
    xor ecx, 32
    lea r12, [r14 + rcx + 64]
    mov ecx, eax
    and ecx, 4
    shl ecx, 3
    lea r10, [r14 + rcx + 128]
    xor ecx, 32
    lea r13, [r14 + rcx + 128]
    # The triangle test's (`RayTri4::with_axis_avx`): the dominant axis kz, the direction,
    # 1/d and the origin permuted to (kx, ky, kz), the shear.
    vshufps xmm8, xmm2, xmm2, 0x10                  # |d| x x y
    vshufps xmm9, xmm2, xmm2, 0x29                  # |d| y z z
    vcmpltps xmm9, xmm9, xmm8
    vmovmskps ecx, xmm9
    and ecx, 7
    lea rdx, [rip + .Lmrk_dominant]
    movzx ecx, byte ptr [rdx + rcx]                 # kz
    mov edx, ecx
    shl edx, 4
    lea rbx, [rip + .Lmrk_permute]
    vmovdqa xmm10, xmmword ptr [rbx + rdx]
    vpermilps xmm11, xmm1, xmm10                    # d permuted
    vpermilps xmm12, xmm5, xmm10                    # 1/d permuted
    vpermilps xmm13, xmm0, xmm10                    # origin permuted
    lea rdx, [rcx + 2 * rcx]
    lea rbx, [rip + .Lmrk_axes]
    mov rax, qword ptr [rbx + 8 * rdx]
    mov qword ptr [rsp + MRK_F_KB], rax
    mov rax, qword ptr [rbx + 8 * rdx + 8]
    mov qword ptr [rsp + MRK_F_KB + 8], rax
    mov rax, qword ptr [rbx + 8 * rdx + 16]
    mov qword ptr [rsp + MRK_F_KB + 16], rax
    vshufps xmm3, xmm12, xmm12, 0xaa                # sz: 1/d[kz] ...
    vshufps xmm9, xmm11, xmm11, 0xaa
    vandps xmm8, xmm9, xmmword ptr [rip + .Lmrk_abs]
    vucomiss xmm8, dword ptr [rip + .Lmrk_tiny]
    jae .Lsz_\any
    vmovaps xmm3, xmmword ptr [rip + .Lmrk_one]     # ... or 1 / d[kz] where RayBox changed it
    vdivps xmm3, xmm3, xmm9
.Lsz_\any:
    vmulps xmm11, xmm11, xmm3                       # sx, sy
    vbroadcastss ymm8, xmm11
    vmovaps ymmword ptr [rsp + MRK_F_SX], ymm8
    vpermilps xmm8, xmm11, 0x55
    vbroadcastss ymm8, xmm8
    vmovaps ymmword ptr [rsp + MRK_F_SY], ymm8
    vbroadcastss ymm8, xmm3
    vmovaps ymmword ptr [rsp + MRK_F_SZ], ymm8
    vbroadcastss ymm8, xmm13
    vmovaps ymmword ptr [rsp + MRK_F_OKX], ymm8
    vpermilps xmm8, xmm13, 0x55
    vbroadcastss ymm8, xmm8
    vmovaps ymmword ptr [rsp + MRK_F_OKY], ymm8
    vpermilps xmm8, xmm13, 0xaa
    vbroadcastss ymm8, xmm8
    vmovaps ymmword ptr [rsp + MRK_F_OKZ], ymm8
    vbroadcastss ymm8, dword ptr [rip + .Lmrk_one]
    vmovaps ymmword ptr [rsp + MRK_F_ONE], ymm8
    # t_min (`t_start`: never below 0), the ray's end and its widening.
    vmovss xmm8, dword ptr [rsi + 24]
    vxorps xmm9, xmm9, xmm9
    vmaxss xmm8, xmm8, xmm9
    vbroadcastss ymm9, xmm8
    vmovaps ymmword ptr [rsp + MRK_F_TMIN], ymm9
    vmovss xmm8, dword ptr [rsi + 28]
    vmovss dword ptr [rdi + {t_best}], xmm8
    vmulss xmm8, xmm8, dword ptr [rip + .Lmrk_far_eps]
    vmovss dword ptr [rdi + {t_wide}], xmm8
    vbroadcastss ymm10, xmm8
    mov dword ptr [rdi + {found}], 0
    # The box test's splats, from the registers.
    vpermilps xmm8, xmm7, 0xaa
    vbroadcastss ymm8, xmm8
    vpermilps xmm15, xmm7, 0x55
    vbroadcastss ymm15, xmm15
    vbroadcastss ymm14, xmm7                        # -FAR_EPS/d: ymm14 ymm15 ymm8, moved below
    vpermilps xmm5, xmm6, 0xaa
    vbroadcastss ymm5, xmm5
    vpermilps xmm4, xmm6, 0x55
    vbroadcastss ymm4, xmm4
    vbroadcastss ymm3, xmm6
    vpermilps xmm2, xmm0, 0xaa
    vbroadcastss ymm2, xmm2
    vpermilps xmm1, xmm0, 0x55
    vbroadcastss ymm1, xmm1
    vbroadcastss ymm0, xmm0
    vmovaps ymm6, ymm14
    vmovaps ymm7, ymm15
    mov rsi, qword ptr [rdi + {stack}]
    mov qword ptr [rsp + MRK_F_STACK], rsi
    mov rax, qword ptr [rdi + {limit}]
    mov qword ptr [rsp + MRK_F_LIMIT], rax
    mov rax, qword ptr [rdi + {root}]
    jmp .Ldescend_\any

    .p2align 4
.Lpop_\any:
    cmp rsi, qword ptr [rsp + MRK_F_STACK]
    je .Lempty_\any
    sub rsi, 16
.if \any == 0
    # Beyond the closest hit: skipped.
    vmovss xmm11, dword ptr [rsi + 12]
    vucomiss xmm11, xmm10
    ja .Lpop_\any
.endif
    mov rax, qword ptr [rsi]

    .p2align 4
.Ldescend_\any:
    bt rax, 62
    jc .Lleaf_\any
    # An inner node or a link (followed alike: every tile is checked): its byte offset.
    mov rcx, rax
    shl rcx, 28
    shr rcx, 20
    # The box test (`RayBox::test_avx2`): (o - plane) * -1/d, reduced as integers.
    vsubps ymm11, ymm0, ymmword ptr [r8 + rcx]
    vsubps ymm12, ymm1, ymmword ptr [r9 + rcx]
    vsubps ymm13, ymm2, ymmword ptr [r10 + rcx]
    vmulps ymm11, ymm11, ymm3
    vmulps ymm12, ymm12, ymm4
    vmulps ymm13, ymm13, ymm5
    vpmaxsd ymm11, ymm11, ymm12
    vpmaxsd ymm13, ymm13, ymm9
    vpmaxsd ymm11, ymm11, ymm13
    vsubps ymm12, ymm0, ymmword ptr [r11 + rcx]
    vsubps ymm13, ymm1, ymmword ptr [r12 + rcx]
    vsubps ymm14, ymm2, ymmword ptr [r13 + rcx]
    vmulps ymm12, ymm12, ymm6
    vmulps ymm13, ymm13, ymm7
    vmulps ymm14, ymm14, ymm8
    vpminsd ymm12, ymm12, ymm13
    vpminsd ymm14, ymm14, ymm10
    vpminsd ymm12, ymm12, ymm14
    # The node's child references, asked for with its boxes.
    lea rdx, [r14 + rcx + {child}]
    prefetcht0 byte ptr [rdx]
    vpcmpgtd ymm12, ymm11, ymm12
    vmovmskps ecx, ymm12
    xor ecx, 0xff
    jz .Lpop_\any
    tzcnt ebx, ecx
    blsr ecx, ecx
    jnz .Lmany_\any
    mov rax, qword ptr [rdx + 8 * rbx]
    jmp .Ldescend_\any

    .p2align 4
.Lmany_\any:
    # Two or more children: pushes ahead (rax still the node's reference).
    cmp rsi, qword ptr [rsp + MRK_F_LIMIT]
    ja .Lfull_\any
.if \any
    # Any hit ends the ray: no sorting by distance, but the far side of the node's splits
    # first (`FAR_HIGH`, as `Tracer::walk`).
    cmp byte ptr [rsp + MRK_F_HIGH], 0
    jne .Lanyhigh_\any
    # From the first slot up: the first child next, the others pushed from the last down.
.Lanylow_\any:
    bsr ebp, ecx
    btr ecx, ebp
    MRK_PUSH_ANY
    test ecx, ecx
    jnz .Lanylow_\any
    mov rax, qword ptr [rdx + 8 * rbx]
    jmp .Ldescend_\any
.Lanyhigh_\any:
    # From the last slot down: the last child next, the others pushed from the first up.
    bts ecx, ebx
    bsr ebx, ecx
    btr ecx, ebx
.Lanyloop_\any:
    tzcnt ebp, ecx
    blsr ecx, ecx
    MRK_PUSH_ANY
    test ecx, ecx
    jnz .Lanyloop_\any
    mov rax, qword ptr [rdx + 8 * rbx]
    jmp .Ldescend_\any
.else
    vmovdqa ymmword ptr [rsp + MRK_F_NEAR], ymm11
    mov r15, qword ptr [rdx + 8 * rbx]                        # a
    vmovss xmm13, dword ptr [rsp + MRK_F_NEAR + 4 * rbx]
    tzcnt ebx, ecx
    blsr ecx, ecx
    mov rbp, qword ptr [rdx + 8 * rbx]                        # b
    vmovss xmm14, dword ptr [rsp + MRK_F_NEAR + 4 * rbx]
    # (near, far) = (b, a) if b.t < a.t, else (a, b)
    vucomiss xmm13, xmm14
    mov rax, r15
    cmova rax, rbp
    cmova rbp, r15
    vminss xmm15, xmm14, xmm13
    vmaxss xmm14, xmm13, xmm14
    test ecx, ecx
    jnz .Lthree_\any
    mov qword ptr [rsi], rbp
    mov dword ptr [rsi + 8], -1
    vmovss dword ptr [rsi + 12], xmm14
    add rsi, 16
    MRK_PREFETCH rbp, rbx, r15
    jmp .Ldescend_\any
.Lthree_\any:
    # Three or more: far and near pushed, the rest sorted in place, far to near; the
    # nearest, on top, taken off again as the next to visit.
    mov qword ptr [rsi], rbp
    mov dword ptr [rsi + 8], -1
    vmovss dword ptr [rsi + 12], xmm14
    mov qword ptr [rsi + 16], rax
    mov dword ptr [rsi + 24], -1
    vmovss dword ptr [rsi + 28], xmm15
    MRK_PREFETCH rbp, rbx, r15
    MRK_PREFETCH rax, rbx, r15
    mov rbp, rsi
    add rsi, 32
.Linsert_\any:
    tzcnt ebx, ecx
    blsr ecx, ecx
    mov rax, qword ptr [rdx + 8 * rbx]
    vmovss xmm13, dword ptr [rsp + MRK_F_NEAR + 4 * rbx]
    MRK_PREFETCH rax, rbx, r15
    mov rbx, rsi
.Lshift_\any:
    cmp rbx, rbp
    jbe .Lplace_\any
    vucomiss xmm13, dword ptr [rbx - 4]
    jbe .Lplace_\any
    vmovaps xmm14, xmmword ptr [rbx - 16]
    vmovaps xmmword ptr [rbx], xmm14
    sub rbx, 16
    jmp .Lshift_\any
.Lplace_\any:
    mov qword ptr [rbx], rax
    mov dword ptr [rbx + 8], -1
    vmovss dword ptr [rbx + 12], xmm13
    add rsi, 16
    test ecx, ecx
    jnz .Linsert_\any
    sub rsi, 16
    mov rax, qword ptr [rsi]
    jmp .Ldescend_\any
.endif

    .p2align 4
.Lleaf_\any:
    test rax, rax
    js .Lpop_\any                       # an empty slot
    mov rdx, rax
    shr rdx, 40
    movzx edx, dl
    shl rax, 24
    shr rax, 24
    mov qword ptr [rsp + MRK_F_UNIT], rax
    mov dword ptr [rsp + MRK_F_LEFT], edx
    mov rbx, qword ptr [rsp + MRK_F_KB]
    mov rbp, qword ptr [rsp + MRK_F_KB + 8]
    mov r15, qword ptr [rsp + MRK_F_KB + 16]
    .p2align 4
.Lblock_\any:
    mov rax, qword ptr [rsp + MRK_F_UNIT]
    shl rax, 4
    add rax, r14
    mov edx, dword ptr [rsp + MRK_F_LEFT]
    cmp edx, 4
    jbe .Lone_\any
    mov ecx, 0xff
    bzhi ecx, ecx, edx
    MRK_TRI 8, ymm, \any, .Lmiss8_\any, .Lexact_\any
    MRK_RECORD
.if \any
    mov eax, 1
    jmp .Lout_\any
.endif
.Lmiss8_\any:
    add qword ptr [rsp + MRK_F_UNIT], 18
    sub dword ptr [rsp + MRK_F_LEFT], 8
    ja .Lblock_\any
    MRK_RELOAD
    jmp .Lpop_\any
.Lone_\any:
    mov ecx, 0xf
    bzhi ecx, ecx, edx
    MRK_TRI 4, xmm, \any, .Lmiss4_\any, .Lexact_\any
    MRK_RECORD
.if \any
    mov eax, 1
    jmp .Lout_\any
.endif
.Lmiss4_\any:
    MRK_RELOAD
    jmp .Lpop_\any

.Lexact_\any:
    # An edge on the ray: the rest of the leaf, from this block, for the driver.
    mov rax, qword ptr [rsp + MRK_F_UNIT]
    mov qword ptr [rdi + {xunit}], rax
    mov eax, dword ptr [rsp + MRK_F_LEFT]
    mov dword ptr [rdi + {xcount}], eax
    mov eax, 2
    jmp .Lout_\any
.Lfull_\any:
    # No room for a node's children: the node is visited again once the driver made room.
    mov qword ptr [rdi + {root}], rax
    mov eax, 3
    jmp .Lout_\any
.Lempty_\any:
    xor eax, eax
.Lout_\any:
    mov qword ptr [rdi + {sp}], rsi
    mov rsp, qword ptr [rsp + MRK_F_SAVED]
    pop r15
    pop r14
    pop r13
    pop r12
    pop rbx
    pop rbp
    vzeroupper
    ret
.endm

    .text
MRK_WALK megaray_walk_closest, 0
MRK_WALK megaray_walk_any, 1

    .section .rodata.megaray_walk,"a",@progbits
    .p2align 4
.Lmrk_abs:
    .long 0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff
.Lmrk_sign:
    .long 0x80000000, 0x80000000, 0x80000000, 0x80000000
.Lmrk_tiny:
    .long {tiny}, {tiny}, {tiny}, {tiny}
.Lmrk_one:
    .long 0x3f800000, 0x3f800000, 0x3f800000, 0x3f800000
.Lmrk_far_eps:
    .long {far_eps}, {far_eps}, {far_eps}, {far_eps}
.Lmrk_permute:                  # PERMUTE: the lanes (kx, ky, kz, 3) of each dominant axis
    .long 1, 2, 0, 3
    .long 2, 0, 1, 3
    .long 0, 1, 2, 3
.Lmrk_axes:                     # AXES_BYTES: 16 * (kx, ky, kz) of each dominant axis
    .quad 16, 32, 0
    .quad 32, 0, 16
    .quad 0, 16, 32
.Lmrk_dominant:                 # DOMINANT: the axis of each outcome of (x, x, y) > (y, z, z)
    .byte 2, 2, 2, 0, 1, 2, 1, 0
    .text
