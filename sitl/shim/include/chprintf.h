/* drivecheck SITL shim: chprintf/chsnprintf (our own declarations; backed by vsnprintf). */
#ifndef SITL_CHPRINTF_H
#define SITL_CHPRINTF_H
#include <stdarg.h>
#include <stddef.h>
typedef struct sitl_stream BaseSequentialStream;
int chvprintf(BaseSequentialStream *chp, const char *fmt, va_list ap);
int chprintf(BaseSequentialStream *chp, const char *fmt, ...);
int chsnprintf(char *str, size_t size, const char *fmt, ...);
int chvsnprintf(char *str, size_t size, const char *fmt, va_list ap);
#endif
