/*
 * Preloaded into Debian's User-Mode-Linux kernel by tools/vcan-guest, so that UML boots on
 * hosts whose XSAVE area is larger than the part UML saves (seen: a 6.18 host kernel on a CPU
 * with AMX, where UML panics with "ptrace set fp regs failed, errno = 14").
 *
 * Why: UML switches its guest threads' FPU state with PTRACE_SETREGSET(NT_X86_XSTATE), giving
 * the XSAVE area it sized at boot (2696 bytes: x87/SSE, AVX, AVX-512). Linux accepts only a whole
 * buffer of the target's user XSAVE size (arch/x86/kernel/fpu/regset.c, xstateregs_set:
 * "count != user_size -> -EFAULT"), 11008 bytes with AMX tile data.
 *
 * What: only when the host refuses such a write with EFAULT, read the target's whole area,
 * lay UML's bytes over its start (UML's components and header), and write the whole area back.
 * The components UML does not know (AMX tiles, which no guest program has permission to use)
 * keep the target's own state. The accepted size is found once and kept. Every other ptrace
 * call goes to libc unchanged, and on a host that accepts UML's buffer nothing here runs.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <elf.h>
#include <errno.h>
#include <stdarg.h>
#include <string.h>
#include <sys/ptrace.h>
#include <sys/syscall.h>
#include <sys/types.h>
#include <sys/uio.h>
#include <unistd.h>

enum { XSAVE_ALIGNMENT = 64 };

static unsigned char whole_area[64 * 1024] __attribute__((aligned(XSAVE_ALIGNMENT)));
static size_t accepted_size;

static long raw_ptrace(long request, pid_t pid, void *addr, void *data)
{
    return syscall(SYS_ptrace, request, pid, addr, data);
}

static long set_whole_area(pid_t pid, size_t size)
{
    struct iovec iov = { whole_area, size };
    return raw_ptrace(PTRACE_SETREGSET, pid, (void *)NT_X86_XSTATE, &iov);
}

/* The host's user XSAVE size lies between UML's size and what PTRACE_GETREGSET returns. */
static long set_padded_xstate(pid_t pid, const struct iovec *given)
{
    struct iovec whole = { whole_area, sizeof whole_area };
    if (raw_ptrace(PTRACE_GETREGSET, pid, (void *)NT_X86_XSTATE, &whole) < 0)
        return -1;
    if (given->iov_len > whole.iov_len) {
        errno = EFAULT;
        return -1;
    }
    memcpy(whole_area, given->iov_base, given->iov_len);
    if (accepted_size)
        return set_whole_area(pid, accepted_size);
    for (size_t size = whole.iov_len; size >= given->iov_len; size -= XSAVE_ALIGNMENT) {
        if (set_whole_area(pid, size) == 0) {
            accepted_size = size;
            return 0;
        }
        if (errno != EFAULT && errno != EINVAL)
            return -1;
        if (size < given->iov_len + XSAVE_ALIGNMENT)
            break;
    }
    errno = EFAULT;
    return -1;
}

long ptrace(enum __ptrace_request request, ...)
{
    static long (*libc_ptrace)(enum __ptrace_request, ...);
    va_list args;
    va_start(args, request);
    pid_t pid = va_arg(args, pid_t);
    void *addr = va_arg(args, void *);
    void *data = va_arg(args, void *);
    va_end(args);
    if (!libc_ptrace)
        libc_ptrace = (long (*)(enum __ptrace_request, ...))dlsym(RTLD_NEXT, "ptrace");
    long result = libc_ptrace(request, pid, addr, data);
    if (result < 0 && errno == EFAULT && request == PTRACE_SETREGSET && (long)addr == NT_X86_XSTATE)
        return set_padded_xstate(pid, data);
    return result;
}
