/* Force-included (-include) when build_fmu.py compiles binaries/linux64: binds the libm
 * functions whose default symbol version glibc raised after 2.17 to their original x86_64
 * versions, so the FMU loads on any glibc >= 2.17 (the manylinux2014 baseline) although it
 * is built on a newer one.
 *
 * glibc 2.29 gave exp, exp2, log, log2 and pow new versions (new implementations without the
 * SVID error wrapper), glibc 2.27 the float ones, glibc 2.35 hypot (the same: no SVID wrapper).  The old versions remain in every later
 * glibc; there they wrap the same new implementation, so the numbers are the same, only
 * errno handling on overflow differs (the FMU never reads errno).  A function the sources
 * do not call leaves no reference.  tests/test_fmu_native_strict.py reads the binary's
 * symbol versions and fails on anything newer than GLIBC_2.17.
 *
 * Shipped in sources/ (so the GUID covers it) but not used when `fmpy compile` builds from
 * <SourceFiles>: a binary built on the machine that runs it needs no pinning.
 */
#ifndef FOURBAR_GLIBC_COMPAT_H
#define FOURBAR_GLIBC_COMPAT_H

#if defined(__linux__) && defined(__x86_64__)   /* and glibc: build_fmu.py includes it only then */
__asm__(".symver exp,exp@GLIBC_2.2.5");
__asm__(".symver exp2,exp2@GLIBC_2.2.5");
__asm__(".symver log,log@GLIBC_2.2.5");
__asm__(".symver log2,log2@GLIBC_2.2.5");
__asm__(".symver pow,pow@GLIBC_2.2.5");
__asm__(".symver hypot,hypot@GLIBC_2.2.5");
__asm__(".symver expf,expf@GLIBC_2.2.5");
__asm__(".symver exp2f,exp2f@GLIBC_2.2.5");
__asm__(".symver logf,logf@GLIBC_2.2.5");
__asm__(".symver log2f,log2f@GLIBC_2.2.5");
__asm__(".symver powf,powf@GLIBC_2.2.5");
#endif

#endif
