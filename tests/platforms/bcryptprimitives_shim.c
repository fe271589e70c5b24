/* Test-only stand-in for bcryptprimitives.dll under Wine 8.0, which lacks ProcessPrng (Rust's
 * std on Windows imports it; every Windows 10 and later has it). It is never shipped: the test
 * puts it next to the harness and tells Wine to prefer it (WINEDLLOVERRIDES). Random bytes
 * come from advapi32's RtlGenRandom (SystemFunction036), which Wine implements. */
#include <windows.h>
BOOLEAN WINAPI SystemFunction036(PVOID buffer, ULONG length);
__declspec(dllexport) BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T length) {
    while (length > 0) {
        ULONG chunk = length > 0x10000000 ? 0x10000000 : (ULONG)length;
        if (!SystemFunction036(data, chunk)) return FALSE;
        data += chunk;
        length -= chunk;
    }
    return TRUE;
}
