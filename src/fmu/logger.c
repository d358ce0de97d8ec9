/* SPDX-License-Identifier: MIT OR Apache-2.0
 *
 * FMI 2.0's logger callback is C-variadic (the message is a printf format), which stable Rust cannot
 * define: this formats the message and hands it to fdimc's Rust side (src/fmu/messages.rs). A message
 * of any length is kept whole; a NULL message or category is tolerated, as exporters pass them. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

void fdimc_fmu_log(void *environment, int status, const char *category, const char *message);

void fdimc_fmi2_logger(void *environment, const char *instance_name, int status, const char *category,
                       const char *message, ...) {
    char small[1024];
    va_list args;
    int n;
    char *big;
    (void)instance_name;
    if (message == NULL) {
        fdimc_fmu_log(environment, status, category, "(the FMU logged no message)");
        return;
    }
    va_start(args, message);
    n = vsnprintf(small, sizeof small, message, args);
    va_end(args);
    if (n < 0) {
        fdimc_fmu_log(environment, status, category, message);
        return;
    }
    if ((size_t)n < sizeof small) {
        fdimc_fmu_log(environment, status, category, small);
        return;
    }
    big = malloc((size_t)n + 1);
    if (big == NULL) {
        fdimc_fmu_log(environment, status, category, small);
        return;
    }
    va_start(args, message);
    vsnprintf(big, (size_t)n + 1, message, args);
    va_end(args);
    fdimc_fmu_log(environment, status, category, big);
    free(big);
}
