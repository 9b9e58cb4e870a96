// GraspGuide: the few C/C++ runtime hooks a newlib-nano bare-metal image needs, kept
// minimal. There is no heap: malloc, _sbrk and operator new trap, so heap use is a link
// error in the size report (the symbols would be kept) and a halt at run time.
// Assertions, pure virtual calls and abort trap too, without pulling in stdio.
#include <sys/stat.h>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <new>

extern "C" {

// Why the firmware stopped; a debugger or QEMU test reads these two words.
volatile int m4f_halt_reason = 0;
volatile int m4f_exit_code = 0;

enum : int {
  kHaltExit = 1,
  kHaltHeap = 2,
  kHaltAssert = 3,
  kHaltPureVirtual = 4,
  kHaltAbort = 5,
};

// Weak so that a QEMU test image can replace it (e.g. with a semihosting exit).
__attribute__((weak, noreturn)) void m4f_halt(int reason, int code) {
  m4f_halt_reason = reason;
  m4f_exit_code = code;
  __asm volatile("cpsid i" ::: "memory");
  for (;;) {
  }
}

__attribute__((noreturn)) void _exit(int status) { m4f_halt(kHaltExit, status); }
__attribute__((noreturn)) void abort(void) { m4f_halt(kHaltAbort, -1); }
__attribute__((noreturn)) void __assert_func(const char*, int line, const char*, const char*) {
  m4f_halt(kHaltAssert, line);
}
__attribute__((noreturn)) void __cxa_pure_virtual(void) { m4f_halt(kHaltPureVirtual, -1); }

// No heap. The _r variants are what newlib calls internally.
__attribute__((noreturn)) static void no_heap() { m4f_halt(kHaltHeap, -1); }
void* _sbrk(ptrdiff_t) { no_heap(); }
void* malloc(size_t) { no_heap(); }
void* calloc(size_t, size_t) { no_heap(); }
void* realloc(void*, size_t) { no_heap(); }
void free(void* p) {
  if (p) no_heap();
}
struct _reent;
void* _malloc_r(struct _reent*, size_t) { no_heap(); }
void* _calloc_r(struct _reent*, size_t, size_t) { no_heap(); }
void* _realloc_r(struct _reent*, void*, size_t) { no_heap(); }
void _free_r(struct _reent*, void* p) {
  if (p) no_heap();
}

// Static objects are never destroyed (the firmware never returns from main), so their
// destructors need not be registered: this keeps newlib's atexit tables out.
void* __dso_handle = nullptr;
int __cxa_atexit(void (*)(void*), void*, void*) { return 0; }
int atexit(void (*)(void)) { return 0; }

// Minimal POSIX stubs: no files, no console (output is discarded).
int _write(int, const char*, int len) { return len; }
int _read(int, char*, int) { return 0; }
int _close(int) { return -1; }
int _lseek(int, int, int) { return 0; }
int _fstat(int, struct stat* st) {
  st->st_mode = S_IFCHR;
  return 0;
}
int _isatty(int) { return 1; }
int _getpid(void) { return 1; }
int _kill(int, int) {
  errno = EINVAL;
  return -1;
}

}  // extern "C"

// C++ allocation traps too (the library versions would call malloc and throw).
void* operator new(size_t) { no_heap(); }
void* operator new[](size_t) { no_heap(); }
void* operator new(size_t, const std::nothrow_t&) noexcept { no_heap(); }
void* operator new[](size_t, const std::nothrow_t&) noexcept { no_heap(); }
void operator delete(void* p) noexcept {
  if (p) no_heap();
}
void operator delete[](void* p) noexcept {
  if (p) no_heap();
}
void operator delete(void* p, size_t) noexcept {
  if (p) no_heap();
}
void operator delete[](void* p, size_t) noexcept {
  if (p) no_heap();
}
