#ifndef SEMIHOST_H
#define SEMIHOST_H
void sh_write0(const char *text); /* a NUL-terminated string to the host's console */
void sh_exit(int ok);             /* end the emulation: exit status 0 if ok */
#endif
